// Canonical order of a Duplex-GS cell's splats (docs/modes.md#duplex): the blend walks a cell's visible splats in this
// order, so an image does not depend on how the scene lists the members of a cell. The CPU module sorts each cell
// with it; the CUDA driver sorts by depth bits on the device and orders equal depths with it (duplex.cu: the two
// functions at the end, which tests/render/test_duplex_order.py runs on the host against the former quadratic rank).
#pragma once

#include <cstring>

#include "common.h"

namespace gbv {

// The raw bits of a float (as uint32).
GBV_HD uint32_t float_bits(float v) {
#if defined(__CUDA_ARCH__)
    return __float_as_uint(v);
#else
    uint32_t u;
    std::memcpy(&u, &v, 4);
    return u;
#endif
}

// Field i (0..11) of a splat for splat_less: depth first.
GBV_HD float splat_key(const Splat2D& s, int i) {
    switch (i) {
        case 0:
            return s.depth;
        case 1:
            return s.xy.x;
        case 2:
            return s.xy.y;
        case 3:
            return s.opacity;
        case 4:
            return s.conic[0];
        case 5:
            return s.conic[1];
        case 6:
            return s.conic[2];
        case 7:
            return s.color[0];
        case 8:
            return s.color[1];
        case 9:
            return s.color[2];
        case 10:
            return s.radius;
        default:
            return s.log_min_alpha;
    }
}

// Total order on a preprocessed splat's fields, depth first, each compared as its raw uint32 bits (depth > 0, so
// depth bits order as depths). Identical keys mean identical splats for the blend. Field by field, so that a
// comparison reads only the fields up to the first difference (a device sort keeps few registers live).
GBV_HD bool splat_less(const Splat2D& a, const Splat2D& b) {
    for (int i = 0; i < 12; ++i) {
        const uint32_t ua = float_bits(splat_key(a, i)), ub = float_bits(splat_key(b, i));
        if (ua != ub) return ua < ub;
    }
    return false;
}

// Member sort key of a splat culled by preprocess (CUDA duplex): after every depth.
constexpr uint32_t ORDER_INVISIBLE = 0xFFFFFFFFu;

// After a stable sort of each cell's member slots by depth bits (keys; values: the splats; ORDER_INVISIBLE for a
// culled one), whether slot j shares its depth bits with a neighbouring slot of the same cell: such runs are the
// only slots whose place splat_less still decides. O(1) per slot.
GBV_HD bool in_depth_run(int64_t j, int64_t num_slots, const uint32_t* keys, const uint32_t* values,
                         const int32_t* cell_of) {
    const uint32_t key = keys[j];
    if (key == ORDER_INVISIBLE) return false;
    const int32_t c = cell_of[values[j]];
    return (j > 0 && keys[j - 1] == key && cell_of[values[j - 1]] == c) ||
           (j + 1 < num_slots && keys[j + 1] == key && cell_of[values[j + 1]] == c);
}

// Whether run slots p and q (in_depth_run) belong to one run: runs are contiguous, so same cell and depth bits.
GBV_HD bool same_depth_run(uint32_t p, uint32_t q, const uint32_t* keys, const uint32_t* values,
                           const int32_t* cell_of) {
    return keys[p] == keys[q] && cell_of[values[p]] == cell_of[values[q]];
}

// The canonical order of the run slots in linear time (duplex.cu): list them in slot order, number their runs
// (same_depth_run of neighbours), then sort the list stably by splat_key field RUN_PASSES - 1 .. 1 and last by run
// number (least significant first, as a radix sort): each run's slots end up in splat_less order (field 0, the
// depth, is equal within a run), ties in slot order, runs where they were. Pass `pass` (0 .. RUN_PASSES - 1) sorts
// by run_pass_key.
constexpr int RUN_PASSES = 12;
GBV_HD uint32_t run_pass_key(int pass, uint32_t slot, uint32_t run, const uint32_t* values, const Splat2D* splats) {
    const int field = RUN_PASSES - 1 - pass;
    return field == 0 ? run : float_bits(splat_key(splats[values[slot]], field));
}

}  // namespace gbv
