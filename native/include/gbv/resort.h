// The per-pixel order of the sorted modes (eval3d, stopthepop; their fragments are ray3d.h's sorted_fragment): a
// pixel's fragments arrive in its tile list's order (by centre depth) and are blended in the order of their depth,
// ties in list order. StopThePop's queue of K fragments (r4dl/StopThePop-Rasterization,
// cuda_rasterizer/stopthepop/hierarchical_render.cuh, front4OneFromMid): when the queue is full its nearest fragment
// is blended before the next one is inserted, behind queued fragments of equal depth; what is left is blended in
// order at the end of the list. K = 0: the exact order. The CPU (native/cpu/blend_sorted.h) and CUDA
// (native/cuda/blend.cu) walks share these steps.
#pragma once

#include "blend.h"
#include "common.h"

namespace gbv {

struct Fragment {
    float depth, alpha;
    int32_t entry;  // list position
};

// Insert f into the queue q[0..n) sorted by depth, behind the fragments of equal depth.
GBV_HD void queue_insert(Fragment* q, int& n, const Fragment& f) {
    int k = n;
    for (; k > 0 && q[k - 1].depth > f.depth; --k) q[k] = q[k - 1];
    q[k] = f;
    ++n;
}

// Remove the queue's front q[0].
GBV_HD void queue_pop(Fragment* q, int& n) {
    for (int k = 1; k < n; ++k) q[k - 1] = q[k];
    --n;
}

// Whether fragment a comes before b in the exact order (depth, then list position).
GBV_HD bool fragment_before(const Fragment& a, const Fragment& b) {
    return a.depth < b.depth || (a.depth == b.depth && a.entry < b.entry);
}

// Blend one fragment as 3DGS does (composite_scalar); true when the pixel stops.
template <class Tr>
GBV_HD bool blend_fragment(const Fragment& f, const float color[3], AlphaState<Lanes1>& st) {
    GBV_TRACE(Tr, entry(f.entry, SKIP_NONE));
    const bool done = composite_scalar<Lanes1, Tr>(true, f.alpha, color, st);
    if (done) GBV_TRACE(Tr, stopped(true));
    GBV_TRACE(Tr, after(st));
    return done;
}

}  // namespace gbv
