// One tile's pixels, blended in groups of L::N lanes (a row segment of the tile): the splats of the tile's list go
// front to back through the steps of gbv/blend.h for every lane at once, lanes drop out as they terminate, and the
// group stops when none is left. Instantiated for Lanes1 (scalar path, blend_scalar.cpp) and for Highway's vector
// lanes (blend_isa.cpp, once per instruction set). The TileJob interface (tile_job.h) is plain data, so the units
// built for different instruction sets share nothing but these types. A tracer type (gbv/trace.h) follows the walk:
// renders use NoTrace; the pixel trace (trace.cpp) runs the Lanes1 instance on a one-pixel rectangle with a recorder.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "blend_sorted.h"
#include "gbv/stochastic.h"
#include "tile_job.h"

namespace gbv {
namespace tile {

template <class L, class Tr>
void group_alpha(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    AlphaState<L> st = {L::set(1.0f), {L::set(0.0f), L::set(0.0f), L::set(0.0f)}};
    if (job.mode == ANALYTIC)
        walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
            const typename L::M stop = blend_analytic<L, Tr>(s, g.px, g.py, live, st);
            GBV_TRACE(Tr, after(st));
            return stop;
        });
    else
        walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
            const typename L::M stop = blend_scalar<L, Tr>(s, g.px, g.py, live, st);
            GBV_TRACE(Tr, after(st));
            return stop;
        });
    for (int c = 0; c < 3; ++c) L::store(st.C[c], out.C[c]);
    L::store(st.T, out.T);
}

// The group box of gaussian_blending: every lane's window centre, grown by the largest half perimeter (a lane
// rejects a splat farther than radius + half perimeter from its window centre) and by float rounding.
template <class L, class B>
void window_box(const WindowState<L>& win, B& g) {
    const float reach = 0.5f * L::reduce_max(win.w + win.h) + 1e-3f;
    g.xa = L::reduce_min(win.x) - reach;
    g.xb = L::reduce_max(win.x) + reach;
    g.ya = L::reduce_min(win.y) - reach;
    g.yb = L::reduce_max(win.y) + reach;
    const float slack = 1e-6f * (fabsf(g.xa) + fabsf(g.xb) + fabsf(g.ya) + fabsf(g.yb));
    g.xa -= slack;
    g.xb += slack;
    g.ya -= slack;
    g.yb += slack;
}

// The lane type of each half of L (LanesX2's Half), void where L has no halves.
template <class L, class = void>
struct HalfOf {
    using type = void;
};
template <class L>
struct HalfOf<L, std::void_t<typename L::Half>> {
    using type = typename L::Half;
};

// Half k of a two-half window state as the half lane type's state, and back.
template <class H, class W>
WindowState<H> get_half(const W& w, int k) {
    const auto h = [k](const auto& p) { return k ? p.b : p.a; };
    return {h(w.T), h(w.x), h(w.y), h(w.w), h(w.h), {h(w.C[0]), h(w.C[1]), h(w.C[2])}};
}
template <class H, class W>
void set_half(W& w, int k, const WindowState<H>& v) {
    const auto h = [k](auto& p) -> typename H::F& { return k ? p.b : p.a; };
    h(w.T) = v.T;
    h(w.x) = v.x;
    h(w.y) = v.y;
    h(w.w) = v.w;
    h(w.h) = v.h;
    for (int c = 0; c < 3; ++c) h(w.C[c]) = v.C[c];
}

// gaussian_blending on a group of two halves (AVX2's 2 x 8 lanes), each with its own window box: a splat whose bounds
// miss one half's box cannot pass the cut-off in any of its lanes, so the other half takes it alone at half the work.
// Bit-identical to stepping both halves: a step changes only lanes that pass the cut-off, and everything it decides
// for the whole group (which branches run, the series length) depends on those lanes only. The list is filtered
// (Filtered) by the box around both halves' boxes, which moves less often than either.
template <class L, bool Fast>
void walk_gaussian_halves(const TileJob& job, typename L::M live, Cursor entries, WindowState<L>& win, Out<L::N>& out) {
    using H = typename HalfOf<L>::type;
    Box box[2];
    bool alive[2] = {H::any(live.a), H::any(live.b)};
    for (int k = 0; k < 2; ++k) window_box<H>(get_half<H>(win, k), box[k]);
    for (int i = 0; i < L::N; ++i) out.evals[i] = job.n;
    // both halves' boxes in y (a NaN side kept: it leaves the band, as in the one-box walk)
    const auto lower = [](float a, float b) { return a != a || b != b ? a + b : std::min(a, b); };
    const auto upper = [](float a, float b) { return a != a || b != b ? a + b : std::max(a, b); };
    Filtered hits(entries);
    for (int i;;) {
        const Box both = {lower(box[0].xa, box[1].xa), upper(box[0].xb, box[1].xb), lower(box[0].ya, box[1].ya),
                          upper(box[0].yb, box[1].yb)};
        if ((i = hits.next(job.n, job.bounds, both)) < 0) break;
        const SplatBounds& b = job.bounds[i];
        const bool in[2] = {alive[0] && !outside(b, box[0].xa, box[0].xb, box[0].ya, box[0].yb),
                            alive[1] && !outside(b, box[1].xa, box[1].xb, box[1].ya, box[1].yb)};
        if (!in[0] && !in[1]) continue;
        typename L::M stop;
        if (in[0] && in[1]) {
            typename L::M took = L::none();
            stop = blend_gaussian<L, NoTrace, Fast>(job.list[i], live, win, &took);
            for (int k = 0; k < 2; ++k)
                if (H::any(k ? took.b : took.a)) window_box<H>(get_half<H>(win, k), box[k]);
        } else {
            const int k = in[1];
            WindowState<H> half = get_half<H>(win, k);
            typename H::M took = H::none();
            const typename H::M s = blend_gaussian<H, NoTrace, Fast>(job.list[i], k ? live.b : live.a, half, &took);
            set_half<H>(win, k, half);
            if (H::any(took)) window_box<H>(half, box[k]);
            stop = k ? typename L::M{H::none(), s} : typename L::M{s, H::none()};
        }
        const uint32_t bits = L::bits(stop);
        if (!bits) continue;
        for (int k = 0; k < L::N; ++k)
            if ((bits >> k) & 1u) out.evals[k] = i + 1;
        live = L::and_not(live, stop);
        alive[0] = H::any(live.a);
        alive[1] = H::any(live.b);
        if (!alive[0] && !alive[1]) break;
    }
}

template <class L, class Tr, bool Fast>
void group_gaussian(const TileJob& job, Group<L> g, Out<L::N>& out) {
    const typename L::F one = L::set(1.0f), zero = L::set(0.0f);
    WindowState<L> win = {one, g.px, g.py, one, one, {zero, zero, zero}};
    if constexpr (!std::is_void_v<typename HalfOf<L>::type> && std::is_same_v<Tr, NoTrace>) {
        walk_gaussian_halves<L, Fast>(job, g.live, g.entries, win, out);
    } else {
        window_box<L>(win, g);
        // chunks of entries on vector lanes (a one-pixel group's box moves at nearly every take: there they cost more)
        walk<L, Tr, (L::N > 1)>(job, g, out, [&](const Splat2D& s, typename L::M live) {
            typename L::M took = L::none();
            const typename L::M stop = blend_gaussian<L, Tr, Fast>(s, live, win, &took);
            if (L::any(took)) window_box<L>(win, g);
            GBV_TRACE(Tr, after(win));
            return stop;
        });
    }
    for (int c = 0; c < 3; ++c) L::store(win.C[c], out.C[c]);
    L::store(win.T, out.T);
    L::store(win.w, out.wx);
    L::store(win.h, out.wy);
}

// stochastic (gbv/stochastic.h): each lane's sample key once per group, then the list until every lane kept a
// fragment.
template <class L, class Tr>
void group_stochastic(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    uint32_t keys[L::N];
    for (int k = 0; k < L::N; ++k) keys[k] = stochastic_sample_key(job.frame_key, (uint32_t)(g.x + k), (uint32_t)g.y);
    AlphaState<L> st = {L::set(1.0f), {L::set(0.0f), L::set(0.0f), L::set(0.0f)}};
    walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
        const typename L::M stop = blend_stochastic<L, Tr>(s, g.px, g.py, live, keys, st);
        GBV_TRACE(Tr, after(st));
        return stop;
    });
    for (int c = 0; c < 3; ++c) L::store(st.C[c], out.C[c]);
    L::store(st.T, out.T);
}

// stochastic_popfree: the same keys; every lane walks the whole list, depth-testing its kept fragments.
template <class L, class Tr>
void group_popfree(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    uint32_t keys[L::N];
    for (int k = 0; k < L::N; ++k) keys[k] = stochastic_sample_key(job.frame_key, (uint32_t)(g.x + k), (uint32_t)g.y);
    const typename L::F zero = L::set(0.0f);
    PopfreeState<L> st = {L::set(1.0f), L::set(-std::numeric_limits<float>::infinity()), {zero, zero, zero}};
    walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
        blend_stochastic_popfree<L, Tr>(s, job.planes[s.id], g.px, g.py, live, keys, st);
        GBV_TRACE(Tr, after(st));
        return L::none();
    });
    for (int c = 0; c < 3; ++c) L::store(st.C[c], out.C[c]);
    L::store(st.T, out.T);
}

template <class L, class Tr>
void group_wsr(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    WsrSumsN<L::N> acc = {};
    walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
        blend_wsr<L, Tr>(s, g.px, g.py, live, acc);
        return L::none();
    });
    for (int k = 0; k < L::N; ++k) {
        const int64_t C[3] = {acc.C[0][k], acc.C[1][k], acc.C[2][k]};
        const PixelSums sums = wsr_pixel_sums(C, acc.S[k]);
        for (int c = 0; c < 3; ++c) out.C[c][k] = sums.C[c];
        out.T[k] = sums.T;
        out.S[k] = sums.S;
    }
}

// eval3d and stopthepop, one pixel after another (blend_sorted.h; the scalar path only: frame.cpp runs it for these
// modes on every SIMD path).
template <class L, class Tr>
void group_sorted(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    static_assert(L::N == 1, "the per-pixel sorted modes have no vector lanes");
    AlphaState<Lanes1> st = {1.0f, {0.0f, 0.0f, 0.0f}};
    const int queue = job.mode == EVAL3D ? 0 : job.queue;
    const int x = (int)floorf(L::reduce_max(g.px)), y = (int)floorf(L::reduce_max(g.py));
    out.evals[0] = blend_sorted_pixel<Tr>(job.list, job.rays, job.n, job.mode, queue, job.tile_x0, job.tile_y0, x, y,
                                          job.hier, st);
    for (int c = 0; c < 3; ++c) out.C[c][0] = st.C[c];
    out.T[0] = st.T;
}

template <class L, class Tr>
void group_duplex(const TileJob& job, const Group<L>& g, Out<L::N>& out) {
    const typename L::F one = L::set(1.0f), zero = L::set(0.0f);
    DuplexLanes<L> st = {one, one, L::seti(-1), zero, {zero, zero, zero}};
    walk<L, Tr>(job, g, out, [&](const Splat2D& s, typename L::M live) {
        const typename L::M stop = blend_duplex<L, Tr>(s, g.px, g.py, live, job.oit.et_grade, st);
        GBV_TRACE(Tr, after(st));
        return stop;
    });
    L::store(st.T, out.T);
    L::store(st.S, out.S);
    for (int c = 0; c < 3; ++c) L::store(st.C[c], out.C[c]);
}

}  // namespace tile

// Blend every pixel of the job's tile and write its finished colour and alpha (resolve_pixel), evals and
// (gaussian_blending) the final window size. A lane group is one row segment of L::N pixels, or a block of
// job.group_rows rows of L::N / group_rows pixels where the job asks for it (a lane per pixel either way).
template <class L, class Tr = NoTrace>
void blend_tile(const TileJob& job) {
    constexpr int N = L::N;
    const int rows = N % job.group_rows == 0 ? job.group_rows : 1, cols = N / rows;
    float offsets[N], row_offsets[N];
    for (int k = 0; k < N; ++k) offsets[k] = (float)(k % cols) + 0.5f, row_offsets[k] = (float)(k / cols) + 0.5f;
    const typename L::F lane_offset = L::load(offsets), row_offset = L::load(row_offsets);
    tile::Out<N> out = {};  // S stays 0 where the mode has no weight sum
    for (int y = job.y0; y < job.y1; y += rows) {
        for (int x = job.x0; x < job.x1; x += cols) {
            tile::Group<L> g;
            g.x = x;
            g.y = y;
            g.count = job.x1 - x < cols ? job.x1 - x : cols;  // pixels per row
            g.px = L::set((float)x) + lane_offset;  // x + k + 0.5 exactly, as one pixel computes it
            g.py = L::set((float)y) + row_offset;
            g.live =
                rows == 1 ? L::first_n(g.count) : L::and_(g.px < L::set((float)job.x1), g.py < L::set((float)job.y1));
            g.xa = (float)x + 0.5f;
            g.xb = (float)(x + g.count - 1) + 0.5f;
            g.ya = (float)y + 0.5f;
            g.yb = (float)(std::min(y + rows, job.y1) - 1) + 0.5f;
            g.entries = {nullptr, 0, 0.0f, 0.0f};
            if constexpr (std::is_same_v<Tr, NoTrace>) {  // a trace records every entry's test: the whole list
                if (job.bands) {
                    const Bands& b = *job.bands;
                    const int r = (y - job.y0) / job.group_rows;
                    g.entries = {b.idx.data() + b.start[r], (int)(b.start[r + 1] - b.start[r]), b.lo[r], b.hi[r]};
                }
            }
            switch (job.mode) {
                case GAUSSIAN_BLENDING:
                    if (job.fast)
                        tile::group_gaussian<L, Tr, true>(job, g, out);
                    else
                        tile::group_gaussian<L, Tr, false>(job, g, out);
                    break;
                case WSR:
                    tile::group_wsr<L, Tr>(job, g, out);
                    break;
                case DUPLEX:
                    tile::group_duplex<L, Tr>(job, g, out);
                    break;
                case STOCHASTIC:
                    tile::group_stochastic<L, Tr>(job, g, out);
                    break;
                case STOCHASTIC_POPFREE:
                    tile::group_popfree<L, Tr>(job, g, out);
                    break;
                case EVAL3D:
                case STOPTHEPOP:
                    if constexpr (L::N == 1) tile::group_sorted<L, Tr>(job, g, out);
                    break;
                default:
                    tile::group_alpha<L, Tr>(job, g, out);
                    break;
            }
            for (int k = 0; k < N; ++k) {
                if (k % cols >= g.count || y + k / cols >= job.y1) continue;
                const size_t p = (size_t)(y + k / cols - job.y0) * job.width + (x - job.x0) + k % cols;
                const PixelSums sums = {{out.C[0][k], out.C[1][k], out.C[2][k]}, out.T[k], out.S[k]};
                const float total =
                    resolve_pixel(job.mode, sums, job.oit.weight_background, job.bg, job.rgb + p * 3, job.alpha + p);
                GBV_TRACE(Tr, resolved(total));
                job.evals[p] = out.evals[k];
                if (job.window) {
                    job.window[p * 2] = out.wx[k];
                    job.window[p * 2 + 1] = out.wy[k];
                }
            }
        }
    }
}

}  // namespace gbv
