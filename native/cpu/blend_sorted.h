// The per-pixel sorted modes' walk of a tile list (eval3d, stopthepop): each pixel takes the list's fragments (a splat
// that adds alpha >= 1/255 there, gbv/ray3d.h: sorted_fragment) in the list's order (the frame's global order by
// centre depth) and blends them front to back in its own order by the depth of their maximum along its ray.
//
// stopthepop:K (K > 0): a sorted queue of K fragments per pixel, as StopThePop's per-thread head queue
// (r4dl/StopThePop-Rasterization, cuda_rasterizer/stopthepop/hierarchical_render.cuh, front4OneFromMid): when the
// queue is full the nearest fragment is blended before the next is inserted, a new fragment goes behind queued ones of
// equal depth, and the rest are blended in order at the end of the list. A fragment arriving after a deeper one was
// blended stays out of order: the published method's approximation. The published kernel's sub-tile levels before
// the head queue (a 4x4 queue of 64 and a 2x2 queue of 8, each sorted by the depth at its centre ray) are not
// modelled. K = 0 (and eval3d): every fragment, then a stable sort by depth: the exact per-pixel order. The pixel
// composites as 3DGS (blend.h composite_scalar) and stops where T (1 - alpha) < 1e-4.
//
// One pixel at a time: each pixel has its own order, so there are no vector lanes; every SIMD path runs this one.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "gbv/blend.h"
#include "gbv/ray3d.h"

namespace gbv::tile {

struct Fragment {
    float depth, alpha;
    int32_t entry;  // list position
};

// Blend one pixel (px, py) of `list` (n entries, rays[i] entry i's ray data) into st; returns the pixel's evals: the
// list position at which it stopped (+1), else n.
template <class Tr>
int blend_sorted_pixel(const Splat2D* list, const RaySplat* rays, int n, Mode mode, int queue, float px, float py,
                       AlphaState<Lanes1>& st) {
    thread_local std::vector<Fragment> frags;  // the queue (or every fragment), front first
    frags.clear();
    bool done = false;
    const auto blend = [&](const Fragment& f) {
        GBV_TRACE(Tr, entry(f.entry, SKIP_NONE));
        done = composite_scalar<Lanes1, Tr>(true, f.alpha, list[f.entry].color, st);
        if (done) GBV_TRACE(Tr, stopped(true));
        GBV_TRACE(Tr, after(st));
    };
    const auto by_depth = [](const Fragment& a, const Fragment& b) { return a.depth < b.depth; };
    for (int i = 0; i < n; ++i) {
        Fragment f = {0.0f, 0.0f, i};
        if (!sorted_fragment(mode, list[i], rays[i], px, py, &f.alpha, &f.depth)) continue;
        if (queue > 0 && (int)frags.size() == queue) {
            blend(frags.front());
            frags.erase(frags.begin());
            if (done) return i + 1;
        }
        if (queue > 0)
            frags.insert(std::upper_bound(frags.begin(), frags.end(), f, by_depth), f);
        else
            frags.push_back(f);
    }
    if (queue == 0) std::stable_sort(frags.begin(), frags.end(), by_depth);
    for (const Fragment& f : frags) {
        blend(f);
        if (done) break;
    }
    return n;
}

}  // namespace gbv::tile
