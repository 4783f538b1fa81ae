// nanobind helpers shared by the CPU module (cpu/bindings.cpp) and the CUDA module (cuda/module.cpp): argument checks
// that throw std::invalid_argument (Python ValueError), numpy arrays that own a vector, the result dict.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "gbv/args.h"
#include "gbv/camera.h"
#include "gbv/common.h"

namespace gbv::nbc {

namespace nb = nanobind;
using FArr = nb::ndarray<const float, nb::c_contig, nb::device::cpu>;
using IArr = nb::ndarray<const int32_t, nb::c_contig, nb::device::cpu>;

[[noreturn]] inline void fail(const char* where, const char* what) {
    throw std::invalid_argument(std::string(where) + ": " + what);
}

// A numpy array that takes over the vector's storage.
template <typename T, typename A>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T, A>&& v, std::initializer_list<size_t> shape) {
    auto* heap = new std::vector<T, A>(std::move(v));
    nb::capsule owner(heap, [](void* p) noexcept { delete static_cast<std::vector<T, A>*>(p); });
    return nb::ndarray<nb::numpy, T>(heap->data(), shape, owner);
}

// The keyword names of a scene's arrays, as check_scene takes them (upload, upload_lod and their checks).
#define GBV_SCENE_ARGS                                                                          \
    nb::arg("means"), nb::arg("scales"), nb::arg("quats"), nb::arg("opacities"), nb::arg("sh"), \
        nb::arg("filter_3d").none()

// The scene arrays (activated parameters, as gbviewer.Scene); returns N.
inline int64_t check_scene(const char* where, const FArr& means, const FArr& scales, const FArr& quats,
                           const FArr& opacities, const FArr& sh, const std::optional<FArr>& filter_3d) {
    const int64_t n = means.ndim() == 2 ? (int64_t)means.shape(0) : -1;
    if (n < 0 || means.shape(1) != 3 || scales.size() != (size_t)n * 3 || quats.size() != (size_t)n * 4 ||
        opacities.size() != (size_t)n || sh.ndim() != 3 || sh.shape(0) != (size_t)n || sh.shape(2) != 3 ||
        (filter_3d && filter_3d->size() != (size_t)n))
        fail(where,
             "array shapes do not match (N,3) means/scales, (N,4) quats, (N,) opacities, (N,K,3) sh, "
             "(N,) filter_3d");
    if (sh.shape(1) < 1) fail(where, "sh must hold K >= 1 coefficients per splat (N,K,3), the DC term first");
    return n;
}

// Whether every value of `a` is finite.
inline bool all_finite(const FArr& a) {
    for (size_t i = 0; i < a.size(); ++i)
        if (!std::isfinite(a.data()[i])) return false;
    return true;
}

// A hierarchy's interior nodes for upload_lod: upload's array shapes, and every value finite (the frame's stage
// reads them as it reads the scene's rows, which the Scene checked); returns their count.
inline int64_t check_lod_nodes(const char* where, const FArr& means, const FArr& scales, const FArr& quats,
                               const FArr& opacities, const FArr& sh, const std::optional<FArr>& filter_3d) {
    const int64_t m = check_scene(where, means, scales, quats, opacities, sh, filter_3d);
    if (!(all_finite(means) && all_finite(scales) && all_finite(quats) && all_finite(opacities) && all_finite(sh) &&
          (!filter_3d || all_finite(*filter_3d))))
        fail(where, "the interior arrays hold values that are not finite");
    return m;
}

// Camera pose and background colour.
inline void check_view(const char* where, const FArr& R, const FArr& t, const FArr& background) {
    if (R.size() != 9 || t.size() != 3 || background.size() != 3)
        fail(where, "R must be 3x3, t and background 3 floats");
}

// The mode word: the Mode in its low 8 bits, stopthepop's per-pixel queue length K (0..MAX_QUEUE, 0: unbounded) in
// the bits above (gbviewer.render.RenderSettings.native_mode).
inline Mode check_mode(const char* where, int mode) {
    const int m = mode & 0xff, param = mode >> 8;
    if (mode < 0 || m > STOPTHEPOP) fail(where, "unknown mode");
    if (param != 0 && m != STOPTHEPOP) fail(where, "only stopthepop takes a mode parameter (its queue length)");
    if (param > MAX_QUEUE) fail(where, "stopthepop's queue length must be 0..64");
    return (Mode)m;
}

inline Projection check_projection(const char* where, int projection) {
    if (projection != PERSPECTIVE && projection != ORTHOGRAPHIC)
        fail(where, "projection must be 0 (perspective) or 1 (orthographic)");
    return (Projection)projection;
}

inline void check_supersample(const char* where, int N) {
    if (N < 1 || N > 8) fail(where, "supersample must be 1..8");
}

// The render arguments both modules take (Python: gbviewer.render.prepare.camera_args, then mode, supersample,
// background and the order-independent globals), checked; a bad one throws std::invalid_argument (ValueError) naming
// `where`. Checks: R 3x3, t and background 3 floats, all finite; width and height >= 1 and at most 2^31 - 1 pixels at
// N x N samples; fx, fy, near finite and > 0, cx, cy finite; projection and mode known; N in 1..8; for wsr and duplex
// a finite weight_background >= 0 and, with depth_correct, a finite sigma > 0; for duplex a finite et_grade > 0.
inline RenderArgs parse_render_args(const char* where, const FArr& R, const FArr& t, float fx, float fy, float cx,
                                    float cy, int width, int height, float near_plane, int projection, int mode,
                                    int supersample, const FArr& background, float sigma, float weight_background,
                                    float et_grade, bool depth_correct) {
    check_view(where, R, t, background);
    const Mode md = check_mode(where, mode);
    const Projection proj = check_projection(where, projection);
    check_supersample(where, supersample);
    if (!all_finite(R) || !all_finite(t) || !all_finite(background)) fail(where, "R, t and background must be finite");
    const int N = supersample;
    const int64_t hi_w = (int64_t)width * N, hi_h = (int64_t)height * N;  // each < 2^34: the product fits
    if (width < 1 || height < 1 || hi_w * hi_h > INT32_MAX)
        fail(where, "width and height must be >= 1, with at most 2^31 - 1 pixels at supersample x supersample");
    if (!(std::isfinite(fx) && fx > 0 && std::isfinite(fy) && fy > 0 && std::isfinite(cx) && std::isfinite(cy) &&
          std::isfinite(near_plane) && near_plane > 0))
        fail(where, "fx, fy and near_plane must be finite and > 0, cx and cy finite");
    if (md == WSR || md == DUPLEX) {
        if (!(std::isfinite(weight_background) && weight_background >= 0))
            fail(where, "weight_background must be finite and >= 0");
        if (depth_correct && !(std::isfinite(sigma) && sigma > 0)) fail(where, "sigma must be finite and > 0");
    }
    if (md == DUPLEX && !(std::isfinite(et_grade) && et_grade > 0)) fail(where, "et_grade must be finite and > 0");
    RenderArgs a;
    a.cam = make_camera(R.data(), t.data(), fx * N, fy * N, cx * N, cy * N, width * N, height * N, near_plane, proj);
    a.mode = md;
    a.supersample = supersample;
    a.width = width;
    a.height = height;
    for (int c = 0; c < 3; ++c) a.bg[c] = background.data()[c];
    a.oit = OitParams{sigma, weight_background, et_grade, depth_correct ? 1 : 0};
    if (md == STOPTHEPOP) a.queue = mode >> 8;
    return a;
}

// The scalar mode's viewer filter and rules (gbv/view_filter.h) into `a.oit`: float32 [dilation, pre_dilation,
// cull_lambda, compensate (0 or 1), dc_clamp (0 or 1), support, sort_radial (0 or 1)], each finite and >= 0; none
// keeps 3DGS's (OitParams' defaults).
inline void set_view_filter(const char* where, RenderArgs& a, const std::optional<FArr>& view_filter) {
    if (!view_filter) return;
    const FArr& f = *view_filter;
    if (f.ndim() != 1 || f.shape(0) != 7) fail(where, "view_filter must be float32 (7,)");
    const float* v = f.data();
    for (int i = 0; i < 7; ++i)
        if (!(std::isfinite(v[i]) && v[i] >= 0)) fail(where, "view_filter values must be finite and >= 0");
    for (int i : {3, 4, 6})
        if (v[i] != 0 && v[i] != 1) fail(where, "view_filter compensate, dc_clamp and sort_radial must be 0 or 1");
    a.oit.dilation = v[0];
    a.oit.pre_dilation = v[1];
    a.oit.cull_lambda = v[2];
    a.oit.compensate = v[3] != 0 ? 1 : 0;
    a.oit.dc_clamp = v[4] != 0 ? 1 : 0;
    a.oit.support = v[5];
    a.oit.sort_radial = v[6] != 0 ? 1 : 0;
}

// A render call's RenderArgs: parse_render_args' checks, then the SH degree cap, the window plane, the viewer
// filter, the stochastic mode's seed and frame index and gaussian_blending's precision.
inline RenderArgs render_args(const char* where, const FArr& R, const FArr& t, float fx, float fy, float cx, float cy,
                              int width, int height, float near_plane, int projection, int mode, int supersample,
                              int sh_degree, const FArr& background, bool want_window, float sigma,
                              float weight_background, float et_grade, bool depth_correct,
                              const std::optional<FArr>& view_filter, uint32_t seed = 0, uint32_t frame = 0,
                              bool fast = false) {
    RenderArgs a = parse_render_args(where, R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode,
                                     supersample, background, sigma, weight_background, et_grade, depth_correct);
    a.sh_degree = sh_degree;
    a.want_window = want_window;
    set_view_filter(where, a, view_filter);
    a.seed = seed;
    a.frame = frame;
    a.fast = fast;
    return a;
}

// The sort-free view-weight SH of N splats; returns its K.
inline int check_weight_sh(const char* where, const FArr& weight_sh, int64_t n) {
    const int wk = weight_sh.ndim() == 2 ? (int)weight_sh.shape(1) : -1;
    if (weight_sh.shape(0) != (size_t)n || (wk != 1 && wk != 4 && wk != 9 && wk != 16))
        fail(where, "weight_sh must be (N, K) with K = 1, 4, 9 or 16");
    return wk;
}

// Cell ellipsoids and offsets; returns M.
inline int64_t check_cell_arrays(const char* where, const FArr& means, const FArr& scales, const FArr& quats,
                                 const IArr& offsets) {
    const int64_t m = means.ndim() == 2 ? (int64_t)means.shape(0) : -1;
    if (m < 0 || means.size() != (size_t)m * 3 || scales.size() != (size_t)m * 3 || quats.size() != (size_t)m * 4 ||
        offsets.size() != (size_t)m + 1)
        fail(where, "cells must be (M,3) means and scales, (M,4) quats, (M+1,) offsets");
    return m;
}

// The cell of each of n splats (-1: none) for cells whose cell c holds members[offsets[c] .. offsets[c+1]). Throws
// unless that is a partition: offsets from 0 to num_members, not decreasing, each member a splat of at most one
// cell. gbviewer.model.cells.Cells validates the same in Python; this guards the native reads (O(M + members)).
inline std::vector<int32_t> partition_cell_of(const char* where, const int32_t* offsets, const int32_t* members,
                                              int64_t m, int64_t num_members, int64_t n) {
    std::vector<int32_t> cell_of(n, -1);
    bool ok = offsets[0] == 0 && offsets[m] == num_members;
    for (int64_t c = 0; ok && c < m; ++c) {
        ok = offsets[c] <= offsets[c + 1];
        for (int32_t j = offsets[c]; ok && j < offsets[c + 1]; ++j) {
            ok = members[j] >= 0 && members[j] < n && cell_of[members[j]] < 0;
            if (ok) cell_of[members[j]] = (int32_t)c;
        }
    }
    if (!ok)
        fail(where,
             "cell_offsets / cell_members are not a partition of splats into cells (offsets from 0 to "
             "len(members), each splat in at most one cell)");
    return cell_of;
}

// A render's stats as a dict: per-stage ms, counts, and `evaluations` (the sum of the evaluation counts).
template <class Stats>
nb::dict stats_dict(const Stats& st, int64_t evaluations) {
    nb::dict d;
    d["preprocess_ms"] = st.preprocess_ms;
    d["sort_ms"] = st.sort_ms;
    d["blend_ms"] = st.blend_ms;
    d["visible"] = st.visible;
    d["sort_length"] = st.sort_length;
    d["pairs"] = st.pairs;
    d["cells_visible"] = st.cells_visible;
    d["cell_misses"] = st.cell_misses;
    d["evaluations"] = evaluations;
    return d;
}

// The dict a render returns (gbviewer.render.prepare.native_frame reads it): rgb (H,W,3), alpha, evals (H,W),
// window (H,W,2) when rendered, and stats_dict's fields with evaluations = the sum of evals. `img` has the vectors
// rgb, alpha, evals, window (moved out), `st` the stats fields.
template <class Img, class Stats>
nb::dict result_dict(Img& img, const Stats& st, size_t H, size_t W) {
    int64_t evaluations = 0;
    for (int32_t e : img.evals) evaluations += e;
    nb::dict d = stats_dict(st, evaluations);
    d["rgb"] = to_numpy(std::move(img.rgb), {H, W, 3});
    d["alpha"] = to_numpy(std::move(img.alpha), {H, W});
    d["evals"] = to_numpy(std::move(img.evals), {H, W});
    if (!img.window.empty()) d["window"] = to_numpy(std::move(img.window), {H, W, 2});
    return d;
}

}  // namespace gbv::nbc
