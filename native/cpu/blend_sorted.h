// The per-pixel sorted modes' walk of a tile list on the CPU (eval3d, stopthepop; the rules: gbv/resort.h): each pixel
// takes the list's fragments (gbv/ray3d.h: sorted_fragment) through StopThePop's hierarchy ending in a queue of K
// (stopthepop:K, the list in stage 1's order: tile_depth_order), or (K = 0, and eval3d) all of them and a stable sort
// by depth.
//
// One pixel at a time: each pixel has its own order, so there are no vector lanes; every SIMD path runs this one.
#pragma once

#include <algorithm>
#include <vector>

#include "gbv/ray3d.h"
#include "gbv/resort.h"

namespace gbv::tile {

// The list's splats and rays as resort.h's walk reads them.
struct ListSource {
    const Splat2D* list;
    const RaySplat* rays;
    const Splat2D& splat(int i) const { return list[i]; }
    const RaySplat& ray(int i) const { return rays[i]; }
};

// Blend pixel (x, y) of the tile whose first pixel is (tx0, ty0) from `list` (n entries, rays[i] entry i's ray data)
// into st; returns the pixel's evals (hier_walk's; K = 0: n).
template <class Tr>
int blend_sorted_pixel(const Splat2D* list, const RaySplat* rays, int n, Mode mode, int queue, int tx0, int ty0, int x,
                       int y, AlphaState<Lanes1>& st) {
    if (queue > 0) return hier_walk<ListSource, Tr>({list, rays}, n, queue, tx0, ty0, x, y, st);
    thread_local std::vector<Fragment> all;
    all.clear();
    for (int i = 0; i < n; ++i) {
        Fragment f = {0.0f, 0.0f, i};
        if (sorted_fragment(mode, list[i], rays[i], x + 0.5f, y + 0.5f, &f.alpha, &f.depth)) all.push_back(f);
    }
    std::stable_sort(all.begin(), all.end(), [](const Fragment& a, const Fragment& b) { return a.depth < b.depth; });
    for (const Fragment& f : all)
        if (blend_fragment<Tr>(f, list[f.entry].color, st)) break;
    return n;
}

}  // namespace gbv::tile
