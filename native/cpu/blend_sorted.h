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

// What reaches the pixels of a 2x2 block (hier_stream): a list entry and the entries loaded by then.
struct HierArrival {
    int32_t entry, loaded;
};

// stopthepop's stages 2 and 3 give the four pixels of a 2x2 block the same entries: one tile's streams, each built
// when its block's first pixel is blended (reset for every tile).
struct HierCache {
    static constexpr int BLOCKS = (TILE / 2) * (TILE / 2);
    std::vector<HierArrival> streams[BLOCKS];
    bool ready[BLOCKS];
    void reset() { std::fill(ready, ready + BLOCKS, false); }
};

// The list's splats and rays as resort.h's walk reads them.
struct ListSource {
    const Splat2D* list;
    const RaySplat* rays;
    const Splat2D& splat(int i) const { return list[i]; }
    const RaySplat& ray(int i) const { return rays[i]; }
};

// stopthepop:K's pixel (x, y) through its 2x2 block's stream in `cache` (built here if not yet); as hier_walk.
template <class Tr>
int blend_hier_pixel(const ListSource& src, int n, int K, int tx0, int ty0, int x, int y, HierCache& cache,
                     AlphaState<Lanes1>& st) {
    const HierPixel g = hier_pixel_at(tx0, ty0, x, y);
    const int b = (y - ty0) / 2 * (TILE / 2) + (x - tx0) / 2;
    std::vector<HierArrival>& arrivals = cache.streams[b];
    HierState h;
    h.qn = 0;
    h.done = false;
    if (!cache.ready[b]) {
        arrivals.clear();
        auto record = [&](int entry, int loaded) { arrivals.push_back({entry, loaded}); };
        hier_stream(src, n, g, h, record);
        cache.ready[b] = true;
    }
    int ev = n;
    for (size_t k = 0; k < arrivals.size() && !h.done; ++k)
        hier_arrive<ListSource, Tr>(src, arrivals[k].entry, arrivals[k].loaded, K, g, h, st, &ev);
    hier_finish<ListSource, Tr>(src, h, st);
    return ev;
}

// Blend pixel (x, y) of the tile whose first pixel is (tx0, ty0) from `list` (n entries, rays[i] entry i's ray data)
// into st (stopthepop:K through `cache` when given, else hier_walk); returns the pixel's evals (hier_walk's; K = 0: n).
template <class Tr>
int blend_sorted_pixel(const Splat2D* list, const RaySplat* rays, int n, Mode mode, int queue, int tx0, int ty0, int x,
                       int y, HierCache* cache, AlphaState<Lanes1>& st) {
    if (queue > 0 && cache) return blend_hier_pixel<Tr>({list, rays}, n, queue, tx0, ty0, x, y, *cache, st);
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
