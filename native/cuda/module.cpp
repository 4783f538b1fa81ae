// nanobind module gbviewer._native_cuda: the CUDA renderer behind the same call shape as the CPU module.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>

#include <stdexcept>

#include "gbv/camera.h"
#include "renderer.h"

namespace nb = nanobind;
using namespace gbv;
using FArr = nb::ndarray<const float, nb::c_contig, nb::device::cpu>;
using IArr = nb::ndarray<const int32_t, nb::c_contig, nb::device::cpu>;

namespace {

template <typename T>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T>&& v, std::initializer_list<size_t> shape) {
    auto* heap = new std::vector<T>(std::move(v));
    nb::capsule owner(heap, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::ndarray<nb::numpy, T>(heap->data(), shape, owner);
}

// The camera at N times the output resolution (supersampling renders there, then box-averages).
CameraParams scaled_camera(FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
                           float near_plane, int N) {
    if (R.size() != 9 || t.size() != 3) throw std::invalid_argument("render: R must be 3x3 and t 3 floats");
    if (N < 1 || N > 8) throw std::invalid_argument("render: supersample must be 1..8");
    return make_camera(R.data(), t.data(), fx * N, fy * N, cx * N, cy * N, width * N, height * N, near_plane);
}

Mode check_mode(int mode) {
    if (mode < SCALAR || mode > DUPLEX) throw std::invalid_argument("render: unknown mode");
    return (Mode)mode;
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
                 const int64_t n = (int64_t)means.shape(0);
                 if (means.ndim() != 2 || means.shape(1) != 3 || scales.size() != (size_t)n * 3 ||
                     quats.size() != (size_t)n * 4 || opacities.size() != (size_t)n || sh.ndim() != 3 ||
                     sh.shape(0) != (size_t)n || sh.shape(2) != 3 || (filter_3d && filter_3d->size() != (size_t)n))
                     throw std::invalid_argument("upload: array shapes do not match a Scene");
                 r.upload(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                          filter_3d ? filter_3d->data() : nullptr, n, (int)sh.shape(1));
             })
        .def("upload_weights",
             [](cuda::Renderer& r, FArr weight_sh) {
                 if (weight_sh.ndim() != 2) throw std::invalid_argument("upload_weights: (N, K) view-weight SH");
                 r.upload_weights(weight_sh.data(), (int64_t)weight_sh.shape(0), (int)weight_sh.shape(1));
             })
        .def("upload_cells",
             [](cuda::Renderer& r, FArr means, FArr scales, FArr quats, IArr offsets, IArr members, IArr cell_of) {
                 const int64_t m = (int64_t)means.shape(0);
                 if (scales.size() != (size_t)m * 3 || quats.size() != (size_t)m * 4 || offsets.size() != (size_t)m + 1)
                     throw std::invalid_argument("upload_cells: (M,3) means, scales, (M,4) quats, (M+1,) offsets");
                 r.upload_cells(means.data(), scales.data(), quats.data(), offsets.data(), members.data(),
                                cell_of.data(), m, (int64_t)members.size());
             })
        .def("render",
             [](cuda::Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
                float near_plane, int mode, int supersample, int sh_degree, FArr background, bool want_window,
                float sigma, float weight_background, float et_grade, bool depth_correct) {
                 const CameraParams cam =
                     scaled_camera(R, t, fx, fy, cx, cy, width, height, near_plane, supersample);
                 const float bg[3] = {background.data()[0], background.data()[1], background.data()[2]};
                 const OitParams oit{sigma, weight_background, et_grade, depth_correct ? 1 : 0};
                 cuda::RenderResult res;
                 {
                     nb::gil_scoped_release release;
                     res = r.render(cam, check_mode(mode), supersample, sh_degree, bg, want_window, oit);
                 }
                 int64_t evaluations = 0;
                 for (int32_t e : res.evals) evaluations += e;
                 const size_t H = height, W = width;
                 nb::dict d;
                 d["rgb"] = to_numpy(std::move(res.rgb), {H, W, 3});
                 d["alpha"] = to_numpy(std::move(res.alpha), {H, W});
                 d["evals"] = to_numpy(std::move(res.evals), {H, W});
                 if (!res.window.empty()) d["window"] = to_numpy(std::move(res.window), {H, W, 2});
                 d["preprocess_ms"] = res.preprocess_ms;
                 d["sort_ms"] = res.sort_ms;
                 d["blend_ms"] = res.blend_ms;
                 d["visible"] = res.visible;
                 d["sort_length"] = res.sort_length;
                 d["pairs"] = res.pairs;
                 d["evaluations"] = evaluations;
                 return d;
             })
        .def("render_to_gl_texture",
             [](cuda::Renderer& r, unsigned int texture, FArr R, FArr t, float fx, float fy, float cx, float cy,
                int width, int height, float near_plane, int mode, int supersample, int sh_degree,
                FArr background, float sigma, float weight_background, float et_grade, bool depth_correct) {
                 const CameraParams cam =
                     scaled_camera(R, t, fx, fy, cx, cy, width, height, near_plane, supersample);
                 const float bg[3] = {background.data()[0], background.data()[1], background.data()[2]};
                 const OitParams oit{sigma, weight_background, et_grade, depth_correct ? 1 : 0};
                 r.render_to_gl_texture(texture, cam, check_mode(mode), supersample, sh_degree, bg, oit);
             },
             nb::arg("texture"), nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"),
             nb::arg("cy"), nb::arg("width"), nb::arg("height"), nb::arg("near_plane"), nb::arg("mode"),
             nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"), nb::arg("sigma") = 10.0f,
             nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false,
             "Render into an existing GL_RGBA32F texture of the output size (the GL context must be current).");
}
