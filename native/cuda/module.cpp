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

namespace {

// The keyword names after `R` of render_args' arguments (the renderer methods and check_render_args share them).
#define GBV_RENDER_ARGS                                                                                           \
    nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"), nb::arg("cy"), nb::arg("width"),     \
        nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"), nb::arg("mode"), nb::arg("supersample"), \
        nb::arg("sh_degree"), nb::arg("background"),                                                              \
        nb::arg("want_window") = false, nb::arg("sigma") = 10.0f, nb::arg("weight_background") = 1.0f,            \
        nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false, nb::arg("view_filter").none() = nb::none(), \
        nb::arg("seed") = 0, nb::arg("frame") = 0, nb::arg("fast") = false

// A render's dict with the per-camera stage's stats (stage_reused, stage_ms) and the kernel that ran (fast), as the CPU
// module's.
nb::dict with_stage(nb::dict d, const cuda::RenderResult& res, const RenderArgs& a) {
    d["fast"] = a.fast && a.mode == GAUSSIAN_BLENDING;
    d["stage_reused"] = res.stage_reused;
    d["stage_ms"] = res.stage_ms;
    return d;
}

}  // namespace

NB_MODULE(_native_cuda, m) {
    m.doc() =
        "gbviewer CUDA renderer (same kernel headers as the CPU module). One Renderer may be shared by "
        "threads: its calls are serialised, and every call releases the GIL before it waits for the renderer.";
    nb::exception<cuda::DeviceFailed>(m, "DeviceFailed", PyExc_RuntimeError);
    m.def("availability", &cuda::availability, "(usable, reason or the default device's name)");
    m.def("default_device", &cuda::default_device,
          "The device Renderer() uses on this thread (the runtime's current device); -1 without a usable runtime.");
    m.def("memory_info", &cuda::memory_info, nb::arg("device"), "(free, total) bytes of the device's memory.");
    m.def("gl_devices", &cuda::gl_devices,
          "CUDA devices that drive the OpenGL context current on this thread ([] when none or unknown).");
    m.def("error_info", &cuda::error_info, nb::arg("code"),
          "(CUDA's name of error `code`, whether it raises DeviceFailed without asking the device); no device needed.");
    m.def("grown_capacity", &cuda::grown_capacity, nb::arg("capacity"), nb::arg("n"),
          "Elements a device buffer of `capacity` allocates for a request of n (the growth policy, for tests).");
    m.def(
        "check_render_args",
        [](FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height, float near_plane,
           int projection, int mode, int supersample, int sh_degree, FArr background, bool want_window, float sigma,
           float weight_background, float et_grade, bool depth_correct, std::optional<FArr> view_filter, uint32_t seed,
           uint32_t frame, bool fast) {
            render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode, supersample,
                        sh_degree, background, want_window, sigma, weight_background, et_grade, depth_correct,
                        view_filter, seed, frame, fast);
        },
        GBV_RENDER_ARGS, "Renderer.render's argument checks, without a device: raises ValueError as render would.");
    m.def(
        "check_scene",
        [](FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter_3d) {
            return check_scene("upload", means, scales, quats, opacities, sh, filter_3d);
        },
        GBV_SCENE_ARGS, "Renderer.upload's array checks, without a device; returns N.");
    m.def(
        "check_lod_nodes",
        [](FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter_3d) {
            return check_lod_nodes("upload_lod", means, scales, quats, opacities, sh, filter_3d);
        },
        GBV_SCENE_ARGS, "Renderer.upload_lod's array checks, without a device; returns the node count.");
    nb::class_<cuda::Renderer>(m, "Renderer")
        .def(nb::init<int>(), nb::arg("device") = -1, "device < 0: default_device()")
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
                 nb::gil_scoped_release release;  // the checks read the arrays only (the caller holds them)
                 const cuda::Renderer::SceneInfo scene = r.scene();
                 const int k = check_weight_sh("upload_weights", weight_sh, scene.n);
                 r.upload_weights(weight_sh.data(), scene.n, k, scene.generation);
             })
        .def("upload_cells",
             [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, IArr offsets, IArr members, IArr cell_of) {
                 nb::gil_scoped_release release;
                 const int64_t m = check_cell_arrays("upload_cells", means, scales, quats, offsets);
                 // checked against the scene uploaded now; upload_cells refuses if another replaces it meanwhile
                 const cuda::Renderer::SceneInfo scene = r.scene();
                 const int64_t n = scene.n;
                 const std::vector<int32_t> expect =
                     partition_cell_of("upload_cells", offsets.data(), members.data(), m, (int64_t)members.size(), n);
                 if (cell_of.size() != (size_t)n || !std::equal(expect.begin(), expect.end(), cell_of.data()))
                     throw std::invalid_argument(
                         "upload_cells: cell_of must give each of the scene's splats its cell "
                         "in the partition (-1: none)");
                 r.upload_cells(means.data(), scales.data(), quats.data(), offsets.data(), members.data(),
                                cell_of.data(), m, (int64_t)members.size(), scene.generation);
             })
        .def(
            "upload_lod",
            [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, FArr opacities, FArr sh,
               std::optional<FArr> filter_3d) {
                const int64_t m = check_lod_nodes("upload_lod", means, scales, quats, opacities, sh, filter_3d);
                nb::gil_scoped_release release;
                r.upload_lod(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                             filter_3d ? filter_3d->data() : nullptr, m, (int)sh.shape(1), r.scene().generation);
            },
            GBV_SCENE_ARGS,
            "A level-of-detail hierarchy's interior nodes (as upload's arrays), rows N.. after the scene's.")
        .def(
            "upload_cut",
            [](cuda::Renderer& r, IArr rows, FArr weights) {
                if (rows.size() != weights.size()) fail("upload_cut", "one weight per row expected");
                nb::gil_scoped_release release;
                r.upload_cut(rows.data(), weights.data(), (int64_t)rows.size(), r.scene().generation);
            },
            nb::arg("rows"), nb::arg("weights"),
            "The cut a render with cut=True draws in place: frame splat i is row rows[i] (scene, then nodes), its "
            "opacity times weights[i].")
        .def(
            "render",
            [](cuda::Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
               float near_plane, int projection, int mode, int supersample, int sh_degree, FArr background,
               bool want_window, float sigma, float weight_background, float et_grade, bool depth_correct,
               std::optional<FArr> view_filter, uint32_t seed, uint32_t frame, bool fast, bool cut) {
                const RenderArgs a =
                    render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode,
                                supersample, sh_degree, background, want_window, sigma, weight_background, et_grade,
                                depth_correct, view_filter, seed, frame, fast);
                cuda::RenderResult res;
                {
                    nb::gil_scoped_release release;
                    res = r.render(a, cut);
                }
                return with_stage(result_dict(res, res, (size_t)a.height, (size_t)a.width), res, a);
            },
            GBV_RENDER_ARGS, nb::arg("cut") = false)
        .def(
            "render_to_gl_texture",
            [](cuda::Renderer& r, unsigned int texture, FArr R, FArr t, float fx, float fy, float cx, float cy,
               int width, int height, float near_plane, int projection, int mode, int supersample, int sh_degree,
               FArr background, bool want_window, float sigma, float weight_background, float et_grade,
               bool depth_correct, std::optional<FArr> view_filter, uint32_t seed, uint32_t frame, bool fast,
               bool cut) {
                const RenderArgs a =
                    render_args("render_to_gl_texture", R, t, fx, fy, cx, cy, width, height, near_plane, projection,
                                mode, supersample, sh_degree, background, want_window, sigma, weight_background,
                                et_grade, depth_correct, view_filter, seed, frame, fast);
                cuda::RenderResult res;
                {
                    nb::gil_scoped_release release;
                    res = r.render_to_gl_texture(texture, a, cut);
                }
                return with_stage(stats_dict(res, res.evaluations), res, a);
            },
            nb::arg("texture"), GBV_RENDER_ARGS, nb::arg("cut") = false,
            "Render into an existing GL_RGBA32F texture of the output size (its GL context, or one sharing it, "
            "current on this thread); returns the stats (as render's dict, without the image planes; want_window "
            "is ignored). The texture stays registered with CUDA until release_gl_texture(texture): call that "
            "before deleting it.")
        .def(
            "release_gl_texture",
            [](cuda::Renderer& r, unsigned int texture) {
                nb::gil_scoped_release release;
                r.release_gl_texture(texture);
            },
            nb::arg("texture"), "Drop the texture's CUDA registration (its GL context must be current).")
        .def(
            "release_buffers",
            [](cuda::Renderer& r) {
                nb::gil_scoped_release release;
                r.release_buffers();
            },
            "Forget the scene and free the device buffers (upload again before the next render).");
}
