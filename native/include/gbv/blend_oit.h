// The order-independent modes' blend steps (wsr, duplex) and the normalisation of their weighted sums; blend.h
// describes the lane templates, the NaN rule and the tracer hooks they share.
#pragma once

#include "common.h"
#include "gaussian.h"
#include "lanes.h"
#include "trace.h"

namespace gbv {

// LC-WSR sums per lane: sum of alpha_i c_i and of alpha_i, in 64-bit fixed point with 2^-36 resolution.
// Integer addition is associative, so the sums (and the pixel) are bitwise the same for any order of the
// splats: the CPU's tile lists stay in splat-index order, unsorted, and still give a permutation-invariant
// image. Each float term is rounded once to the fixed-point grid (absolute error <= 2^-37 per term, ~1e-7 after
// 10^4 terms, far below float32 rounding of the final quotient). The GLSL port accumulates in float.
template <int N>
struct WsrSumsN {
    int64_t C[3][N];
    int64_t S[N];
};

// A non-negative float on the fixed-point grid. Terms are clamped to WSR_FIXED_MAX = 2^6, 2^42 on the grid, so
// that a sum of up to 2^21 - 1 terms (2M splats at one pixel) stays below 2^63: no signed overflow.
GBV_HD int64_t to_fixed(float x) { return (int64_t)rintf(minf(x, WSR_FIXED_MAX) * WSR_FIXED_SCALE); }

// `wsr`: sort-free weighted sum (docs/modes.md#wsr): alpha = o' exp(power), no 0.99 clamp, skipped below 1/255,
// C += c alpha, S += alpha; no transmittance and no early termination (never stops a lane). The weight alpha is
// capped at WSR_FIXED_MAX (the fixed-point bound; only huge trained view weights reach it) before it multiplies
// the colour, so a capped splat keeps its colour. The fixed-point sums are added lane by lane.
template <class L, class Tr = NoTrace>
GBV_HD void blend_wsr(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live, WsrSumsN<L::N>& acc) {
    using F = typename L::F;
    using M = typename L::M;
    const F power = gaussian_power<L>(s, L::set(s.xy.x) - px, L::set(s.xy.y) - py);
    M pass = L::and_(live, L::and_(power <= L::set(0.0f), power >= L::set(s.log_min_alpha)));
    GBV_TRACE(Tr, skip(L::and_not(live, power <= L::set(0.0f)), SKIP_POWER));
    GBV_TRACE(Tr, skip(L::and_not(live, pass), SKIP_CUTOFF));
    if (!L::any(pass)) return;
    const F alpha = L::min(L::set(s.opacity) * L::exp(L::select(pass, power, L::set(0.0f))), L::set(WSR_FIXED_MAX));
    GBV_TRACE(Tr, alpha(pass, alpha));
    GBV_TRACE(Tr, skip(L::and_(pass, alpha < L::set(MIN_ALPHA_3DGS)), SKIP_ALPHA));
    pass = L::and_not(pass, alpha < L::set(MIN_ALPHA_3DGS));
    GBV_TRACE(Tr, weight(pass, alpha));
    const uint32_t bits = L::bits(pass);
    if (!bits) return;
    float a[L::N], c[3][L::N];
    L::store(alpha, a);
    for (int k = 0; k < 3; ++k) L::store(L::set(s.color[k]) * alpha, c[k]);
    for (int i = 0; i < L::N; ++i) {
        if (!((bits >> i) & 1u)) continue;
        for (int k = 0; k < 3; ++k) acc.C[k][i] += to_fixed(c[k][i]);
        acc.S[i] += to_fixed(a[i]);
    }
}

// Duplex-GS per-lane state (docs/modes.md#duplex): T = cummult, the product of (1 - alpha/E) over every splat blended
// so far; T_cell = T when the current cell was entered (anchor_correct); the weighted sums C and S.
template <class L>
struct DuplexLanes {
    typename L::F T, T_cell;
    typename L::I cell;
    typename L::F S, C[3];
};

// `duplex`: one splat of a cell-sorted list (cells front to back, a cell's splats in any order). Pixels outside
// the splat's radius are skipped (False Positive Skip); alpha = min(o' exp(power), 0.99), skipped below 1/255. On
// entering a new cell the pixel stops when T < 0.01, else T_cell = T. Then alpha /= E, T *= 1 - alpha, and the
// splat adds with weight alpha T_cell. Inside a cell every weight uses the same T_cell: the cell's sum does not
// depend on the order of its splats (only the float rounding of T does).
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_duplex(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                                  float et_grade, DuplexLanes<L>& st) {
    using F = typename L::F;
    using M = typename L::M;
    const F dx = L::set(s.xy.x) - px, dy = L::set(s.xy.y) - py;
    const M near = L::and_not(live, dx * dx + dy * dy > L::set(s.radius * s.radius));
    GBV_TRACE(Tr, skip(L::and_not(live, near), SKIP_RADIUS));
    if (!L::any(near)) return L::none();
    const F power = gaussian_power<L>(s, dx, dy);
    M pass = L::and_(near, L::and_(power <= L::set(0.0f), power >= L::set(s.log_min_alpha)));
    GBV_TRACE(Tr, skip(L::and_not(near, power <= L::set(0.0f)), SKIP_POWER));
    GBV_TRACE(Tr, skip(L::and_not(near, pass), SKIP_CUTOFF));
    if (!L::any(pass)) return L::none();
    F alpha = L::min(L::set(s.opacity) * L::exp(L::select(pass, power, L::set(0.0f))), L::set(MAX_ALPHA));
    GBV_TRACE(Tr, alpha(pass, alpha));
    GBV_TRACE(Tr, skip(L::and_(pass, alpha < L::set(MIN_ALPHA_3DGS)), SKIP_ALPHA));
    pass = L::and_not(pass, alpha < L::set(MIN_ALPHA_3DGS));
    if (!L::any(pass)) return L::none();
    const M entering = L::and_not(pass, L::eqi(st.cell, L::seti(s.cell)));
    const M stop = L::and_(entering, st.T < L::set(DUPLEX_T_STOP));
    GBV_TRACE(Tr, skip(stop, SKIP_CELL_STOP));
    const M enter = L::and_not(entering, stop);
    st.cell = L::selecti(enter, L::seti(s.cell), st.cell);
    st.T_cell = L::select(enter, st.T, st.T_cell);
    const M add = L::and_not(pass, stop);
    alpha = alpha / L::set(et_grade);
    st.T = L::select(add, st.T * (L::set(1.0f) - alpha), st.T);
    const F w = alpha * st.T_cell;
    GBV_TRACE(Tr, weight(add, w));
    for (int c = 0; c < 3; ++c) st.C[c] = L::select(add, st.C[c] + L::set(s.color[c]) * w, st.C[c]);
    st.S = L::select(add, st.S + w, st.S);
    return stop;
}

// The published normalisation out = (C + bg w_bg) / (S + w_bg T_bg), written as out = C' + T' bg with
// C' = C / S_total and T' = w_bg / S_total (the background's share of the weights; Frame.alpha = 1 - T'). wsr:
// T_bg = 1; duplex: T_bg = the final cummult, and w_bg = 0 once it is below 0.01. A total of exactly 0 becomes
// 1e-4 (LC-WSR; duplex does the same here instead of dividing by zero). Returns S_total.
GBV_HD float resolve_weighted(const float C[3], float S, float wbg, float T_bg, float out_C[3], float* out_T) {
    float total = S + wbg * T_bg;
    if (total == 0.0f) total = WSR_EMPTY_SUM;
    for (int c = 0; c < 3; ++c) out_C[c] = C[c] / total;
    *out_T = wbg / total;
    return total;
}

}  // namespace gbv
