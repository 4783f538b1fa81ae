// The per-pixel order of the sorted modes (eval3d, stopthepop; their fragments are ray3d.h's sorted_fragment).
// eval3d and stopthepop:0: each pixel blends its tile list's fragments in the order of their depth, ties in list order
// (the exact per-pixel sort). stopthepop:K (K > 0) is StopThePop's hierarchical resort (r4dl/StopThePop-Rasterization,
// cuda_rasterizer/stopthepop/hierarchical_render.cuh: sortGaussiansRayHierarchicaEvaluation, with the queue sizes of
// SortQueueSizes and configs/hierarchical.json of r4dl/StopThePop: 4x4 queue 64, 2x2 queue 8, per pixel 4):
//  1. tile: the tile's list sorted by the splat's depth along the ray through the point of the tile's pixel-centre
//     rectangle that the rectangle rule takes as its 2D Gaussian's largest (rect_max_power; PER_TILE_DEPTH_MAXPOS:
//     duplicateWithKeys_extended and max_contrib_power_rect_gaussian_float in stopthepop_common.cuh), as
//     tile_depth_key (ties in centre-depth order; the published radix sort leaves them in splat index order);
//  2. 4x4 sub-tile: the sorted list is loaded 32 entries at a time; entries whose alpha at the sub-tile rectangle's
//     point (the same rule) is below 1/255 are culled (hierarchical_4x4_culling), the rest merged into a queue by the
//     depth along the sub-tile's centre ray (behind queued entries of equal depth); while it holds more than 32, its
//     16 nearest go on, 4 at a time; at the end of the list the rest goes on in order, 4 at a time;
//  3. 2x2 sub-tile: each group of 4 is sorted by the depth along the 2x2 block's centre ray and merged with the 4 it
//     holds (held ones first on ties); the first group is only held, after that the 4 nearest go on in order and the
//     other 4 are held; at the end the held ones go on;
//  4. pixel: each entry that reaches the pixel first blends the queue's nearest fragment if the queue holds K
//     (front4OneFromMid: before the entry is evaluated, so an entry that adds nothing there still pushes one out),
//     then its fragment (alpha and depth t* at the pixel) goes in behind queued fragments of equal depth; the queue
//     is blended in order at the end.
// Each stage's depths compare along one ray, so t* (view z) orders them as the published distance along the unit
// ray does; the tile stage compares different rays and uses that distance. The CPU (native/cpu/blend_sorted.h),
// CUDA (native/cuda/blend.cu) and GLSL (shaders/resort.glsl) walks share these steps (the CPU builds stages 2 and 3
// once per 2x2 block); the tile sort is the binning's (CPU: per tile, stable over the centre-depth list).
#pragma once

#include "blend.h"
#include "common.h"
#include "gaussian.h"
#include "ray3d.h"

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

// Remove the queue's first k entries.
GBV_HD void queue_drop(Fragment* q, int& n, int k) {
    for (int j = k; j < n; ++j) q[j - k] = q[j];
    n -= k;
}

// The hierarchy's sizes: the published 4x4 queue (SortQueueSizes.tile_4x4) and 2x2 queue (tile_2x2, the held group
// and a new one), the list entries a warp loads per round (also the 4x4 queue's fill above which it releases), the
// entries released at a time (pushPullThroughMid) and the group size of the 2x2 merge (front4OneFromMid).
constexpr int HIER_TAIL = 64;
constexpr int HIER_MID = 8;
constexpr int HIER_LOAD = 32;
constexpr int HIER_PULL = 16;
constexpr int HIER_GROUP = 4;
// The tile sort's key is max(0, depth + 8) in float (duplicateWithKeys_extended): depths below -8 tie.
constexpr float TILE_KEY_OFFSET = 8.0f;

// max_contrib_power_rect_gaussian_float (stopthepop_common.cuh): the point (*mx, *my) of the rectangle
// [x0, x0 + w] x [y0, y0 + h] of pixel centres taken as the splat's 2D Gaussian's largest there, and its
// -power: the centre inside; else from the nearest corner, the best step along each edge it is outside of.
GBV_HD float rect_max_power(const Splat2D& s, float x0, float y0, float w, float h, float* mx, float* my) {
    const float a = s.conic[0], b = s.conic[1], c = s.conic[2];
    const float xmd = x0 - s.xy.x, ymd = y0 - s.xy.y;
    const float left = xmd > 0.0f ? 1.0f : 0.0f, above = ymd > 0.0f ? 1.0f : 0.0f;
    const float out_x = left + (s.xy.x > x0 + w ? 1.0f : 0.0f), out_y = above + (s.xy.y > y0 + h ? 1.0f : 0.0f);
    *mx = s.xy.x;
    *my = s.xy.y;
    if (!(out_x + out_y > 0.0f)) return 0.0f;
    const float px = left > 0.0f ? x0 : x0 + w, py = above > 0.0f ? y0 : y0 + h;
    const float dx = xmd < 0.0f ? -w : w, dy = ymd < 0.0f ? -h : h;  // copysign (a difference is never -0)
    const float diffx = s.xy.x - px, diffy = s.xy.y - py;
    const float fx = (mul_rn(mul_rn(dx, a), diffx) + mul_rn(mul_rn(dx, b), diffy)) / mul_rn(mul_rn(w, w), a);
    const float fy = (mul_rn(mul_rn(dy, b), diffx) + mul_rn(mul_rn(dy, c), diffy)) / mul_rn(mul_rn(h, h), c);
    const float tx = fx > 0.0f ? (fx < 1.0f ? fx : 1.0f) : 0.0f, ty = fy > 0.0f ? (fy < 1.0f ? fy : 1.0f) : 0.0f;
    *mx = px + mul_rn(mul_rn(out_y, tx), dx);
    *my = py + mul_rn(mul_rn(out_x, ty), dy);
    const float ex = s.xy.x - *mx, ey = s.xy.y - *my;
    return mul_rn(0.5f, mul_rn(mul_rn(a, ex), ex) + mul_rn(mul_rn(c, ey), ey)) + mul_rn(mul_rn(b, ex), ey);
}

// t* of the splat's maximum along the ray through pixel position (qx, qy) (ray_max).
GBV_HD float ray_depth(const Splat2D& s, const RaySplat& r, float qx, float qy) {
    float t;
    ray_max(r, qx - s.xy.x, qy - s.xy.y, &t);
    return t;
}

// Stage 1's key of a splat in the tile whose first pixel centre is (x0, y0): its depth along the unit ray through
// the rectangle point of rect_max_power (perspective: t* times the length of the ray direction (u, v, 1), with
// (cx, cy, fx, fy) the camera's intrinsics), plus TILE_KEY_OFFSET, floored at 0 (never negative: the GPU binning
// sorts its float bits).
GBV_HD float tile_depth_key(const Splat2D& s, const RaySplat& r, float x0, float y0, float cx, float cy, float fx,
                            float fy) {
    float mx, my;
    rect_max_power(s, x0, y0, (float)(TILE - 1), (float)(TILE - 1), &mx, &my);
    float t = ray_depth(s, r, mx, my);
    if (r.ortho == 0) {
        const float u = (mx - cx) / fx, v = (my - cy) / fy;
        t = mul_rn(t, sqrtf(mul_rn(u, u) + mul_rn(v, v) + 1.0f));
    }
    const float key = t + TILE_KEY_OFFSET;
    return key > 0.0f ? key : 0.0f;
}

// Stage 2's cull: the splat's largest alpha over the 4x4 sub-tile whose first pixel centre is (x0, y0) is below 1/255.
GBV_HD bool subtile_culled(const Splat2D& s, float x0, float y0) {
    float mx, my;
    const float p = rect_max_power(s, x0, y0, 3.0f, 3.0f, &mx, &my);
    const float a = minf(MAX_ALPHA, s.opacity * expf(-p));
    return a < MIN_ALPHA_3DGS;
}

// One pixel's state in the hierarchy: the 4x4 queue, the 2x2 queue (mn < 0: no group held yet), the pixel's queue.
struct HierState {
    Fragment tail[HIER_TAIL], mid[HIER_MID], q[MAX_QUEUE];
    int tn, mn, qn;
    bool done;
};

// The geometry of pixel (x, y) in the tile whose first pixel is (tx0, ty0): its centre, its 4x4 sub-tile's first
// pixel centre (published tail_rect_min) and its 2x2 block's centre ray position.
struct HierPixel {
    float px, py, sx, sy, mx, my;
};

GBV_HD HierPixel hier_pixel_at(int tx0, int ty0, int x, int y) {
    const int x4 = tx0 + ((x - tx0) & ~3), y4 = ty0 + ((y - ty0) & ~3);
    const int x2 = tx0 + ((x - tx0) & ~1), y2 = ty0 + ((y - ty0) & ~1);
    return {x + 0.5f, y + 0.5f, x4 + 0.5f, y4 + 0.5f, x2 + 1.0f, y2 + 1.0f};
}

// Stage 4: list entry `entry` reaches the pixel (the splats and rays of the list through src.splat(i), src.ray(i)),
// emitted when `loaded` list entries had been loaded; *ev = loaded where the pixel stops.
template <class Src, class Tr>
GBV_HD void hier_arrive(const Src& src, int entry, int loaded, int K, const HierPixel& g, HierState& h,
                        AlphaState<Lanes1>& st, int* ev) {
    if (h.done) return;
    if (h.qn == K) {
        h.done = blend_fragment<Tr>(h.q[0], src.splat(h.q[0].entry).color, st);
        queue_pop(h.q, h.qn);
        if (h.done) {
            *ev = loaded;
            return;
        }
    }
    Fragment f = {0.0f, 0.0f, entry};
    if (sorted_fragment(STOPTHEPOP, src.splat(entry), src.ray(entry), g.px, g.py, &f.alpha, &f.depth))
        queue_insert(h.q, h.qn, f);
}

// Stage 4's end: the pixel's queue blended in order.
template <class Src, class Tr>
GBV_HD void hier_finish(const Src& src, HierState& h, AlphaState<Lanes1>& st) {
    for (int k = 0; k < h.qn && !h.done; ++k) h.done = blend_fragment<Tr>(h.q[k], src.splat(h.q[k].entry).color, st);
}

// Stage 3: the 4x4 queue's entries tail[first .. first + count) as one group through the 2x2 queue; what goes on
// is emit(entry, loaded).
template <class Src, class Emit>
GBV_HD void hier_group(const Src& src, int first, int count, int loaded, const HierPixel& g, HierState& h, Emit& emit) {
    if (h.done) return;
    Fragment m[HIER_MID];
    int mn = 0;
    for (int k = 0; k < h.mn; ++k) m[mn++] = h.mid[k];
    for (int k = first; k < first + count; ++k) {
        const int e = h.tail[k].entry;
        const Fragment f = {ray_depth(src.splat(e), src.ray(e), g.mx, g.my), 0.0f, e};
        queue_insert(m, mn, f);
    }
    const int gone = h.mn < 0 ? 0 : (mn < HIER_GROUP ? mn : HIER_GROUP);
    h.mn = 0;
    for (int k = gone; k < mn; ++k) h.mid[h.mn++] = m[k];
    for (int k = 0; k < gone; ++k) emit(m[k].entry, loaded);
}

// Stage 2's release of the 4x4 queue's `count` nearest entries, a group at a time.
template <class Src, class Emit>
GBV_HD void hier_release(const Src& src, int count, int loaded, const HierPixel& g, HierState& h, Emit& emit) {
    for (int k = 0; k < count; k += HIER_GROUP)
        hier_group(src, k, count - k < HIER_GROUP ? count - k : HIER_GROUP, loaded, g, h, emit);
    queue_drop(h.tail, h.tn, count);
}

// Stage 2's load of list entry i into the 4x4 queue, unless culled.
template <class Src>
GBV_HD void hier_load(const Src& src, int i, const HierPixel& g, HierState& h) {
    const Splat2D& s = src.splat(i);
    if (subtile_culled(s, g.sx, g.sy)) return;
    const Fragment f = {ray_depth(s, src.ray(i), g.sx + 1.5f, g.sy + 1.5f), 0.0f, i};
    queue_insert(h.tail, h.tn, f);
}

// Stages 2 and 3 over a tile list already in stage 1's order (n entries) for the 2x2 block of g: every entry that
// goes on to the block's pixels, in order, as emit(entry, loaded); stops loading once h.done.
template <class Src, class Emit>
GBV_HD void hier_stream(const Src& src, int n, const HierPixel& g, HierState& h, Emit& emit) {
    h.tn = 0;
    h.mn = -1;
    for (int base = 0; base < n && !h.done; base += HIER_LOAD) {
        const int end = base + HIER_LOAD < n ? base + HIER_LOAD : n;
        for (int i = base; i < end; ++i) hier_load(src, i, g, h);
        while (h.tn > HIER_LOAD && !h.done) hier_release(src, HIER_PULL, end, g, h, emit);
    }
    hier_release(src, h.tn, n, g, h, emit);
    for (int k = 0; k < h.mn && !h.done; ++k) emit(h.mid[k].entry, n);
}

// One pixel of stopthepop:K (K > 0) over a tile list already in stage 1's order: blends into st and returns the
// pixel's evals (the list entries loaded when it stopped, else n).
template <class Src, class Tr>
GBV_HD int hier_walk(const Src& src, int n, int K, int tx0, int ty0, int x, int y, AlphaState<Lanes1>& st) {
    HierState h;
    h.qn = 0;
    h.done = false;
    const HierPixel g = hier_pixel_at(tx0, ty0, x, y);
    int ev = n;
    auto to_pixel = [&](int entry, int loaded) { hier_arrive<Src, Tr>(src, entry, loaded, K, g, h, st, &ev); };
    hier_stream(src, n, g, h, to_pixel);
    hier_finish<Src, Tr>(src, h, st);
    return ev;
}

}  // namespace gbv
