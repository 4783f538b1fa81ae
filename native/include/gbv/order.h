// Canonical order of a Duplex-GS cell's splats (KERNELS.md §8.3): the blend walks a cell's visible splats in this
// order, so an image does not depend on how the scene lists the members of a cell. The CPU module sorts each cell
// with it; the CUDA driver sorts by depth bits on the device and orders equal depths with it (renderer.cu).
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

// Total order on a preprocessed splat's fields, depth first, each compared as its raw uint32 bits (depth > 0, so
// depth bits order as depths). Identical keys mean identical splats for the blend.
GBV_HD bool splat_less(const Splat2D& a, const Splat2D& b) {
    const float ka[12] = {a.depth,    a.xy.x,     a.xy.y,     a.opacity,  a.conic[0], a.conic[1],
                          a.conic[2], a.color[0], a.color[1], a.color[2], a.radius,   a.log_min_alpha};
    const float kb[12] = {b.depth,    b.xy.x,     b.xy.y,     b.opacity,  b.conic[0], b.conic[1],
                          b.conic[2], b.color[0], b.color[1], b.color[2], b.radius,   b.log_min_alpha};
    for (int i = 0; i < 12; ++i) {
        const uint32_t ua = float_bits(ka[i]), ub = float_bits(kb[i]);
        if (ua != ub) return ua < ub;
    }
    return false;
}

}  // namespace gbv
