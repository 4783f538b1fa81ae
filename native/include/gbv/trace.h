// Trace hooks of the blend steps (blend.h) and of the CPU's tile walk (native/cpu/blend_tile.h). The steps and the
// walk have a tracer type parameter Tr and tell it, per lane, why a splat added nothing and the alpha and weight they
// computed, each list entry and the pixel state after it. Every hook goes through GBV_TRACE, which discards it at
// compile time unless Tr records: renders use NoTrace and compile to the same instructions as without hooks (the
// masks and values computed for the tracer are never instantiated). The CPU's pixel trace (native/cpu/trace.cpp)
// uses a recorder of one pixel (Lanes1).
#pragma once

#include "common.h"

// GBV_TRACE(Tr, skip(mask, SKIP_ALPHA)): Tr::skip(mask, SKIP_ALPHA) where the tracer type Tr records, nothing
// otherwise.
#define GBV_TRACE(Tr, call)                  \
    do {                                     \
        if constexpr (Tr::records) Tr::call; \
    } while (0)

namespace gbv {

// Why a list entry added nothing to a pixel: the kernel's own tests, in the order it makes them (the first that
// fails is reported). Values are gbviewer.render.trace.SKIP_REASONS' positions.
enum Skip : int32_t {
    SKIP_NONE = 0,
    SKIP_BOX,  // the pixel centre (gaussian_blending: window) is outside the splat's box: not evaluated
    SKIP_RADIUS,  // outside the splat's radius (duplex: the pixel; gaussian_blending: the window's reach)
    SKIP_POWER,  // Gaussian exponent > 0 or NaN
    SKIP_CUTOFF,  // exponent below ln(min_alpha / opacity), before the exp (gaussian_blending: the splat's
    // largest value on the window is below 1/256)
    SKIP_ALPHA,  // alpha below 1/255 (gaussian_blending: 1/256)
    SKIP_STOP,  // T (1 - alpha) < 1e-4: the pixel stops without this splat
    SKIP_CELL_STOP,  // duplex: a new cell entered with T < 0.01: the pixel stops
    SKIP_DONE,  // the pixel had stopped before this entry: not evaluated
    SKIP_DISCARD,  // stochastic: the fragment's uniform is not below its alpha (discarded)
    SKIP_DEPTH,  // stochastic_popfree: kept, but behind the nearest fragment kept so far (depth test)
};

// The tracer of renders: records nothing. A recording tracer has `records = true` and these static functions (masks:
// the lanes concerned): from the blend steps skip(mask, why), alpha(mask, value), weight(mask, value),
// fallback(mask); from the tile walk entry(i, why) for list entry i (why: SKIP_BOX when skipped before evaluation,
// else SKIP_NONE), stopped(mask) for the lanes that stopped at it, after(state) with the pixel state after it,
// unreached(i, n) for the entries i..n-1 after the pixel stopped, and resolved(total) with the sum of weights the
// pixel's sums were divided by (resolve_pixel: wsr and duplex; 1 in the other modes).
struct NoTrace {
    static constexpr bool records = false;
};

}  // namespace gbv
