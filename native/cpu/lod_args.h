// The CPU module's level-of-detail arguments (bindings.cpp): a frame's LodArgs and the checks of a hierarchy upload.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "../bindings/nb_common.h"

namespace gbv::nbc {

using L64 = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

// Levels of a hierarchy of n >= 1 splats (lod.h Tree): 0, n, then ceil(count / 8) nodes per level up to one root;
// the number of interior nodes. What the cut walks by is checked here (O(levels)).
inline int64_t check_levels(const char* where, const L64& levels, int64_t n) {
    const int64_t L = (int64_t)levels.shape(0);
    const int64_t* lv = levels.data();
    bool ok = L >= 2 && lv[0] == 0 && lv[1] == n && n >= 1 && n <= INT32_MAX;
    for (int64_t l = 1; ok && l + 1 < L; ++l) {
        const int64_t below = lv[l] - lv[l - 1];
        ok = below > 1 && lv[l + 1] - lv[l] == (below + 7) / 8;
    }
    ok = ok && lv[L - 1] - lv[L - 2] == 1;
    if (!ok) fail(where, "levels must count the scene's splats, then ceil(count / 8) nodes per level up to one root");
    return lv[L - 1] - n;
}

// A hierarchy of the uploaded scene's n splats (lod.h Tree): its levels, interior arrays of their total with the
// scene's SH size, every value finite, order a permutation of the splats (the cut's scatter by splat writes each
// weight once: a repeated index would leave one unwritten). What the cut and the stage read is checked here (O(n),
// once per upload); that it was built from this scene is the caller's (Hierarchy.check).
inline void check_lod_upload(int64_t n, const FArr& means, const FArr& scales, const FArr& quats, const FArr& opacities,
                             const FArr& sh, const std::optional<FArr>& filter_3d, const FArr& radius, const FArr& size,
                             const L64& levels, const IArr& order, int scene_k, bool scene_filter) {
    const char* where = "upload_lod";
    const int64_t m = check_levels(where, levels, n);
    if (check_lod_nodes(where, means, scales, quats, opacities, sh, filter_3d) != m || radius.size() != (size_t)m ||
        size.size() != (size_t)m || order.size() != (size_t)n || (int)sh.shape(1) != scene_k ||
        filter_3d.has_value() != scene_filter || n + m > INT32_MAX)
        fail(where, "the interior arrays must hold one row per interior node, with the scene's SH size and 3D filter");
    std::vector<uint8_t> seen((size_t)n, 0);
    for (size_t i = 0; i < order.size(); ++i) {
        const int32_t s = order.data()[i];
        if (s < 0 || s >= n) fail(where, "order holds indices outside the scene");
        if (seen[s]++) fail(where, "order is not a permutation of the splats (an index repeats)");
    }
    if (!(all_finite(radius) && all_finite(size))) fail(where, "the interior arrays hold values that are not finite");
}

// A frame's level of detail: None, or (tau >= 0, band >= 0, eye float32 (3,), focal > 0, orthographic).
inline LodArgs lod_args(const char* where, const nb::handle& lod) {
    LodArgs a;
    if (lod.is_none()) return a;
    const nb::tuple p = nb::cast<nb::tuple>(lod);
    if (p.size() != 5)
        throw std::invalid_argument(std::string(where) + ": lod is (tau, band, eye, focal, orthographic)");
    a.tau = nb::cast<double>(p[0]);
    a.band = nb::cast<double>(p[1]);
    const FArr eye = nb::cast<FArr>(p[2]);
    a.focal = nb::cast<double>(p[3]);
    a.orthographic = nb::cast<bool>(p[4]);
    if (eye.size() != 3) throw std::invalid_argument(std::string(where) + ": lod eye must hold 3 floats");
    for (int c = 0; c < 3; ++c) a.eye[c] = eye.data()[c];
    if (!(std::isfinite(a.tau) && a.tau >= 0 && std::isfinite(a.band) && a.band >= 0 && std::isfinite(a.focal) &&
          a.focal > 0 && std::isfinite(a.eye[0]) && std::isfinite(a.eye[1]) && std::isfinite(a.eye[2])))
        throw std::invalid_argument(std::string(where) + ": lod needs finite tau >= 0, band >= 0, eye, focal > 0");
    return a;
}

}  // namespace gbv::nbc
