// The per-pixel sorted modes' walk of a tile list on the CPU (eval3d, stopthepop; the rules: gbv/resort.h): each pixel
// takes the list's fragments (gbv/ray3d.h: sorted_fragment) in list order through a queue of K (stopthepop:K), or
// (K = 0, and eval3d) all of them and a stable sort by depth. The published kernel's sub-tile levels before the
// per-pixel queue (a 4x4 queue of 64 and a 2x2 queue of 8, each sorted by the depth at its centre ray) are not
// modelled.
//
// One pixel at a time: each pixel has its own order, so there are no vector lanes; every SIMD path runs this one.
#pragma once

#include <algorithm>
#include <vector>

#include "gbv/ray3d.h"
#include "gbv/resort.h"

namespace gbv::tile {

// Blend one pixel (px, py) of `list` (n entries, rays[i] entry i's ray data) into st; returns the pixel's evals: the
// list position at which it stopped (+1), else n.
template <class Tr>
int blend_sorted_pixel(const Splat2D* list, const RaySplat* rays, int n, Mode mode, int queue, float px, float py,
                       AlphaState<Lanes1>& st) {
    Fragment q[MAX_QUEUE];
    int qn = 0;
    thread_local std::vector<Fragment> all;  // K = 0: every fragment
    all.clear();
    for (int i = 0; i < n; ++i) {
        Fragment f = {0.0f, 0.0f, i};
        if (!sorted_fragment(mode, list[i], rays[i], px, py, &f.alpha, &f.depth)) continue;
        if (queue == 0) {
            all.push_back(f);
            continue;
        }
        if (qn == queue) {
            const bool done = blend_fragment<Tr>(q[0], list[q[0].entry].color, st);
            queue_pop(q, qn);
            if (done) return i + 1;
        }
        queue_insert(q, qn, f);
    }
    if (queue == 0) std::stable_sort(all.begin(), all.end(), [](const Fragment& a, const Fragment& b) {
        return a.depth < b.depth;
    });
    const Fragment* rest = queue == 0 ? all.data() : q;
    for (int k = 0, m = queue == 0 ? (int)all.size() : qn; k < m; ++k)
        if (blend_fragment<Tr>(rest[k], list[rest[k].entry].color, st)) break;
    return n;
}

}  // namespace gbv::tile
