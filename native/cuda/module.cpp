// nanobind module gbviewer._native_cuda: the CUDA renderer behind the same call shape as the CPU module.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>

#include <algorithm>
#include <stdexcept>

#include "gbv/camera.h"
#include "nb_common.h"
#include "renderer.h"

namespace nb = nanobind;
using namespace gbv;
using namespace gbv::nbc;

namespace {

// The camera at N times the output resolution (supersampling renders there, then box-averages).
CameraParams scaled_camera(const FArr& R, const FArr& t, float fx, float fy, float cx, float cy, int width,
                           int height, float near_plane, int N) {
    check_supersample("render", N);
    return make_camera(R.data(), t.data(), fx * N, fy * N, cx * N, cy * N, width * N, height * N, near_plane);
}

}  // namespace

NB_MODULE(_native_cuda, m) {
    m.doc() = "gbviewer CUDA renderer (same kernel headers as the CPU module)";
    m.def("availability", &cuda::availability, "(usable, reason or device name)");
    nb::class_<cuda::Renderer>(m, "Renderer")
        .def(nb::init<>())
        .def("upload",
             [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, FArr opacities, FArr sh,
                std::optional<FArr> filter_3d) {
                 const int64_t n = check_scene("upload", means, scales, quats, opacities, sh, filter_3d);
                 r.upload(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                          filter_3d ? filter_3d->data() : nullptr, n, (int)sh.shape(1));
             })
        .def("upload_weights",
             [](cuda::Renderer& r, FArr weight_sh) {
                 const int k = check_weight_sh("upload_weights", weight_sh, r.num_splats());
                 r.upload_weights(weight_sh.data(), r.num_splats(), k);
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
                 r.upload_cells(means.data(), scales.data(), quats.data(), offsets.data(), members.data(),
                                cell_of.data(), m, (int64_t)members.size());
             })
        .def("render",
             [](cuda::Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
                float near_plane, int mode, int supersample, int sh_degree, FArr background, bool want_window,
                float sigma, float weight_background, float et_grade, bool depth_correct) {
                 check_view("render", R, t, background);
                 const Mode md = check_mode("render", mode);
                 const CameraParams cam =
                     scaled_camera(R, t, fx, fy, cx, cy, width, height, near_plane, supersample);
                 const float bg[3] = {background.data()[0], background.data()[1], background.data()[2]};
                 const OitParams oit{sigma, weight_background, et_grade, depth_correct ? 1 : 0};
                 cuda::RenderResult res;
                 {
                     nb::gil_scoped_release release;
                     res = r.render(cam, md, supersample, sh_degree, bg, want_window, oit);
                 }
                 return result_dict(res, res, (size_t)height, (size_t)width);
             })
        .def("render_to_gl_texture",
             [](cuda::Renderer& r, unsigned int texture, FArr R, FArr t, float fx, float fy, float cx, float cy,
                int width, int height, float near_plane, int mode, int supersample, int sh_degree,
                FArr background, float sigma, float weight_background, float et_grade, bool depth_correct) {
                 check_view("render_to_gl_texture", R, t, background);
                 const Mode md = check_mode("render_to_gl_texture", mode);
                 const CameraParams cam =
                     scaled_camera(R, t, fx, fy, cx, cy, width, height, near_plane, supersample);
                 const float bg[3] = {background.data()[0], background.data()[1], background.data()[2]};
                 const OitParams oit{sigma, weight_background, et_grade, depth_correct ? 1 : 0};
                 r.render_to_gl_texture(texture, cam, md, supersample, sh_degree, bg, oit);
             },
             nb::arg("texture"), nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"),
             nb::arg("cy"), nb::arg("width"), nb::arg("height"), nb::arg("near_plane"), nb::arg("mode"),
             nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"), nb::arg("sigma") = 10.0f,
             nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false,
             "Render into an existing GL_RGBA32F texture of the output size (the GL context must be current).");
}
