// nanobind module gbviewer._native_cuda: the CUDA renderer behind the same call shape as the CPU module.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <stdexcept>

#include "../bindings/nb_common.h"
#include "renderer.h"

namespace nb = nanobind;
using namespace gbv;
using namespace gbv::nbc;

NB_MODULE(_native_cuda, m) {
    m.doc() = "gbviewer CUDA renderer (same kernel headers as the CPU module). One Renderer may be shared by "
              "threads: its calls are serialised, and uploads and renders release the GIL.";
    m.def("availability", &cuda::availability, "(usable, reason or the default device's name)");
    m.def("gl_devices", &cuda::gl_devices,
          "CUDA devices that drive the OpenGL context current on this thread ([] when none or unknown).");
    m.def(
        "check_render_args",
        [](FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height, float near_plane,
           int projection, int mode, int supersample, int sh_degree, FArr background, bool want_window, float sigma,
           float weight_background, float et_grade, bool depth_correct) {
            (void)sh_degree;
            (void)want_window;
            parse_render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode,
                              supersample, background, sigma, weight_background, et_grade, depth_correct);
        },
        nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"), nb::arg("cy"), nb::arg("width"),
        nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"), nb::arg("mode"), nb::arg("supersample"), nb::arg("sh_degree"),
        nb::arg("background"), nb::arg("want_window"), nb::arg("sigma") = 10.0f, nb::arg("weight_background") = 1.0f,
        nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false,
        "Renderer.render's argument checks, without a device: raises ValueError as render would.");
    nb::class_<cuda::Renderer>(m, "Renderer")
        .def(nb::init<int>(), nb::arg("device") = -1,
             "device < 0: the runtime's current device (0 unless the thread selected another)")
        .def_prop_ro("device", &cuda::Renderer::device)
        .def("upload",
             [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, FArr opacities, FArr sh,
                std::optional<FArr> filter_3d) {
                 const int64_t n = check_scene("upload", means, scales, quats, opacities, sh, filter_3d);
                 nb::gil_scoped_release release;
                 r.upload(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                          filter_3d ? filter_3d->data() : nullptr, n, (int)sh.shape(1));
             })
        .def("upload_weights",
             [](cuda::Renderer& r, FArr weight_sh) {
                 const int64_t n = r.num_splats();
                 const int k = check_weight_sh("upload_weights", weight_sh, n);
                 nb::gil_scoped_release release;
                 r.upload_weights(weight_sh.data(), n, k);
             })
        .def("upload_cells",
             [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, IArr offsets, IArr members, IArr cell_of) {
                 const int64_t m = check_cell_arrays("upload_cells", means, scales, quats, offsets);
                 const int64_t n = r.num_splats();
                 const std::vector<int32_t> expect =
                     partition_cell_of("upload_cells", offsets.data(), members.data(), m, (int64_t)members.size(), n);
                 if (cell_of.size() != (size_t)n || !std::equal(expect.begin(), expect.end(), cell_of.data()))
                     throw std::invalid_argument("upload_cells: cell_of must give each of the scene's splats its cell "
                                                 "in the partition (-1: none)");
                 nb::gil_scoped_release release;
                 r.upload_cells(means.data(), scales.data(), quats.data(), offsets.data(), members.data(),
                                cell_of.data(), m, (int64_t)members.size());
             })
        .def("render",
             [](cuda::Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
                float near_plane, int projection, int mode, int supersample, int sh_degree, FArr background,
                bool want_window, float sigma, float weight_background, float et_grade, bool depth_correct) {
                 const RenderArgs a = parse_render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane,
                                                        projection, mode, supersample, background, sigma,
                                                        weight_background, et_grade, depth_correct);
                 cuda::RenderResult res;
                 {
                     nb::gil_scoped_release release;
                     res = r.render(a.cam, a.mode, a.supersample, sh_degree, a.bg, want_window, a.oit);
                 }
                 return result_dict(res, res, (size_t)a.height, (size_t)a.width);
             },
             nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"), nb::arg("cy"),
             nb::arg("width"), nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"), nb::arg("mode"),
             nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"), nb::arg("want_window"),
             nb::arg("sigma") = 10.0f, nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f,
             nb::arg("depth_correct") = false)
        .def("render_to_gl_texture",
             [](cuda::Renderer& r, unsigned int texture, FArr R, FArr t, float fx, float fy, float cx, float cy,
                int width, int height, float near_plane, int projection, int mode, int supersample, int sh_degree,
                FArr background, float sigma, float weight_background, float et_grade, bool depth_correct) {
                 const RenderArgs a = parse_render_args("render_to_gl_texture", R, t, fx, fy, cx, cy, width, height,
                                                        near_plane, projection, mode, supersample, background, sigma,
                                                        weight_background, et_grade, depth_correct);
                 cuda::RenderResult res;
                 {
                     nb::gil_scoped_release release;
                     res = r.render_to_gl_texture(texture, a.cam, a.mode, a.supersample, sh_degree, a.bg, a.oit);
                 }
                 return stats_dict(res, res.evaluations);
             },
             nb::arg("texture"), nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"),
             nb::arg("cy"), nb::arg("width"), nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"),
             nb::arg("mode"), nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"), nb::arg("sigma") = 10.0f,
             nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false,
             "Render into an existing GL_RGBA32F texture of the output size (its GL context, or one sharing it, "
             "current on this thread); returns the stats (as render's dict, without the image planes). The texture "
             "stays registered with CUDA until release_gl_texture(texture): call that before deleting it.")
        .def(
            "release_gl_texture",
            [](cuda::Renderer& r, unsigned int texture) {
                nb::gil_scoped_release release;
                r.release_gl_texture(texture);
            },
            nb::arg("texture"), "Drop the texture's CUDA registration (its GL context must be current).");
}
