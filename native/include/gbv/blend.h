// Per-pixel blending steps, one splat at a time, front to back. Shared by every backend; the GLSL port keeps the
// one-pixel functions' names.
//
// Each step is written once, as a template over a lane type L (lanes.h): L::F is one float per pixel lane, L::M
// one flag per lane. A step takes the lanes still blending (`live`) and returns the lanes that finished at this
// splat (early termination); lanes a splat cannot reach are left untouched, and the work is skipped when no lane
// needs it. With L = Lanes1 (one pixel) the steps are the plain per-pixel functions CUDA and the scalar CPU path
// run; the CPU's vector path instantiates them for 8 or 16 pixels. The one-pixel wrappers at the end of each
// section keep the signatures CUDA and the GLSL port use.
//
// NaN rule (every backend): a NaN Gaussian exponent rejects the splat at that pixel.
//
// Every step also has a tracer type parameter Tr (trace.h): renders use NoTrace, whose hooks are discarded at compile
// time; the CPU's pixel trace uses a recorder and learns, at each of the step's own tests, why a splat was skipped,
// and its alpha and weight.
#pragma once

#include "common.h"
#include "lanes.h"
#include "trace.h"

namespace gbv {

// Exponent of the splat's Gaussian at offset (dx, dy) from its centre (eq. 5; either sign of the offset).
template <class L>
GBV_HD typename L::F gaussian_power(const Splat2D& s, typename L::F dx, typename L::F dy) {
    return L::set(-0.5f) * (L::set(s.conic[0]) * dx * dx + L::set(s.conic[2]) * dy * dy) -
           L::set(s.conic[1]) * dx * dy;
}

// ---- scalar transmittance (scalar, mip, analytic) -----------------------------------------------------------------

template <class L>
struct AlphaState {
    typename L::F T, C[3];
};

// Scalar front-to-back compositing of one alpha per lane (3DGS renderCUDA, KERNELS.md §0.7): skip below
// min_alpha; stop without adding the splat when T(1 - alpha) < 1e-4. Returns the lanes that stopped.
template <class L, class Tr = NoTrace>
GBV_HD typename L::M composite_scalar(typename L::M pass, typename L::F alpha, const float color[3],
                                      AlphaState<L>& st) {
    using F = typename L::F;
    using M = typename L::M;
    GBV_TRACE(Tr, alpha(pass, alpha));
    GBV_TRACE(Tr, skip(L::and_(pass, alpha < L::set(MIN_ALPHA_3DGS)), SKIP_ALPHA));
    pass = L::and_not(pass, alpha < L::set(MIN_ALPHA_3DGS));
    const F test_T = st.T * (L::set(1.0f) - alpha);
    const M low = test_T < L::set(T_STOP);
    const M add = L::and_not(pass, low);
    GBV_TRACE(Tr, skip(L::and_(pass, low), SKIP_STOP));
    const F w = alpha * st.T;
    GBV_TRACE(Tr, weight(add, w));
    for (int c = 0; c < 3; ++c) st.C[c] = L::select(add, st.C[c] + L::set(color[c]) * w, st.C[c]);
    st.T = L::select(add, test_T, st.T);
    return L::and_(pass, low);
}

// `scalar` and `mip`: alpha at the pixel centre (eq. 5). Offsets whose power is below
// log_min_alpha = ln((1/255) / opacity) would give alpha < 1/255 and are skipped before the exp.
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_scalar(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                                  AlphaState<L>& st) {
    using F = typename L::F;
    using M = typename L::M;
    const F power = gaussian_power<L>(s, L::set(s.xy.x) - px, L::set(s.xy.y) - py);
    const M pass = L::and_(live, L::and_(power <= L::set(0.0f), power >= L::set(s.log_min_alpha)));
    GBV_TRACE(Tr, skip(L::and_not(live, power <= L::set(0.0f)), SKIP_POWER));
    GBV_TRACE(Tr, skip(L::and_not(live, pass), SKIP_CUTOFF));
    if (!L::any(pass)) return L::none();
    const F alpha = L::min(L::set(s.opacity) * L::exp(L::select(pass, power, L::set(0.0f))), L::set(MAX_ALPHA));
    return composite_scalar<L, Tr>(pass, alpha, s.color, st);
}

// Analytic-Splatting's logistic approximation of the standard normal CDF (KERNELS.md §4):
// sigmoid(1.6x + 0.07x^3), written with exp (the published 0.5 tanh(z/2) + 0.5 is the same function).
template <class L>
GBV_HD typename L::F approx_cdf(typename L::F x) {
    return L::set(1.0f) / (L::set(1.0f) + L::exp(L::neg(L::set(1.6f) * x + L::set(0.07f) * x * x * x)));
}

// `analytic`: mean alpha over the unit pixel, separable in the splat's eigen-frame (Analytic-Splatting).
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_analytic(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                                    AlphaState<L>& st) {
    using F = typename L::F;
    const F dx = px - L::set(s.xy.x), dy = py - L::set(s.xy.y);
    const F u = dx * L::set(s.v1.x) + dy * L::set(s.v1.y);
    const F v = dx * L::set(-s.v1.y) + dy * L::set(s.v1.x);
    const F s1 = L::set(s.sigma1), s2 = L::set(s.sigma2), h = L::set(0.5f);
    const F iu = s1 * (approx_cdf<L>((u + h) / s1) - approx_cdf<L>((u - h) / s1));
    const F iv = s2 * (approx_cdf<L>((v + h) / s2) - approx_cdf<L>((v - h) / s2));
    const F alpha = L::min(L::set(s.opacity * TWO_PI) * iu * iv, L::set(MAX_ALPHA));
    return composite_scalar<L, Tr>(live, alpha, s.color, st);
}

// ---- Gaussian Blending ----------------------------------------------------------------------------------------------

// Zeroth moment of exp(-t^2/2) from 0 to x (paper eq. 13 with sigma = 1), sqrt(pi/2) erf(x/sqrt(2)), given
// e = exp(-x^2/2). erf uses Abramowitz & Stegun 7.1.26 (absolute error < 1.5e-7, about float32 rounding),
// whose exp(-z^2) is that same e: one exp per window edge serves all three moments, and every backend
// (GLSL has no erf) computes the identical function. The first and second moments over [a, b] follow from
// e: I1 = e(a) - e(b), I2 = I0 + a e(a) - b e(b).
template <class L>
GBV_HD typename L::F gaussian_moment0(typename L::F x, typename L::F e) {
    using F = typename L::F;
    const F z = L::abs(x) * L::set(0.7071067811865476f);
    const F t = L::set(1.0f) / (L::set(1.0f) + L::set(0.3275911f) * z);
    const F poly = t * (L::set(0.254829592f) +
                        t * (L::set(-0.284496736f) +
                             t * (L::set(1.421413741f) + t * (L::set(-1.453152027f) + t * L::set(1.061405429f)))));
    const F erf_abs = L::set(1.0f) - poly * e;
    return L::set(SQRT_PI_2) * L::select(x < L::set(0.0f), L::neg(erf_abs), erf_abs);
}

// Moments of exp(-t^2/2) over one window side [c - h, c + h] (splat sigma units), taken about the window centre c:
// I0 = int e, J1 = int (t - c) e, J2 = int (t - c)^2 e. About the centre, the variance of the update is no longer a
// difference of ~u^2-sized terms (the published form cancels ~log10(12 u^2) digits); and for windows up to 2 sigma
// wide (h <= 1) the integrals come from the Taylor series of e(c + s) = e(c) sum_n (-1)^n He_n(c) s^n / n!
// (probabilists' Hermite polynomials, 6 to GB_SERIES_TERMS terms by h: relative error < 5e-6 against float64 for
// every c), because there the closed form (erf differences, A&S erf's 1.5e-7 absolute error) loses up to 2% in the
// splat's tails. Wider windows use the closed form about the centre: J1 = e(a) - e(b) - c I0, J2 = I0 - h (e(a) + e(b)) - c J1.
template <class L>
struct SideMoments {
    typename L::F I0, J1, J2;
};

template <class L>
GBV_HD SideMoments<L> window_side_moments(typename L::F c, typename L::F h, typename L::M live) {
    using F = typename L::F;
    using M = typename L::M;
    const F zero = L::set(0.0f), one = L::set(1.0f), m = L::set(-0.5f);
    const M series = L::and_(live, h <= L::set(GB_SERIES_MAX_HALF_WIDTH));
    const M closed = L::and_not(live, h <= L::set(GB_SERIES_MAX_HALF_WIDTH));
    SideMoments<L> out = {zero, zero, zero};
    if (L::any(closed)) {
        const F cc = L::select(closed, c, zero), hc = L::select(closed, h, one);  // harmless values elsewhere
        const F a = cc - hc, b = cc + hc;
        const F ea = L::exp(m * a * a), eb = L::exp(m * b * b);
        const F I0 = gaussian_moment0<L>(b, eb) - gaussian_moment0<L>(a, ea);
        const F J1 = (ea - eb) - cc * I0;
        const F J2 = I0 - hc * (ea + eb) - cc * J1;
        out = {L::select(closed, I0, zero), L::select(closed, J1, zero), L::select(closed, J2, zero)};
    }
    if (L::any(series)) {
        const F cc = L::select(series, c, zero), hs = L::select(series, h, zero);
        // b_n = (-1)^n He_n(c) h^n / n!;  I0 = 2h e(c) sum_even b_n/(n+1), J1 = 2h^2 e(c) sum_odd b_n/(n+2),
        // J2 = 2h^3 e(c) sum_even b_n/(n+3)
        F he_prev = one, he = cc, p = hs;  // He_{n-1}, He_n, h^n/n! at n = 1
        F s0 = one, s1 = L::neg(p * he) * L::set(1.0f / 3.0f), s2 = L::set(1.0f / 3.0f);
        // terms for the widest lane: float accuracy (< 6e-7 relative) with 6 up to h = 1/4, 10 up to 1/2, 12 up to 1
        const int terms = L::any(L::and_(series, hs > L::set(0.5f)))    ? GB_SERIES_TERMS
                          : L::any(L::and_(series, hs > L::set(0.25f))) ? 10
                                                                       : 6;
        GBV_UNROLL
        for (int n = 2; n <= GB_SERIES_TERMS; ++n) {
            if (n > terms) break;
            const F he_next = cc * he - L::set((float)(n - 1)) * he_prev;
            he_prev = he;
            he = he_next;
            p = p * hs * L::set(1.0f / (float)n);
            if (n % 2 == 0) {
                const F b = p * he;
                s0 = s0 + b * L::set(1.0f / (float)(n + 1));
                s2 = s2 + b * L::set(1.0f / (float)(n + 3));
            } else {
                s1 = s1 - p * he * L::set(1.0f / (float)(n + 2));
            }
        }
        const F two_h_e = L::set(2.0f) * hs * L::exp(m * cc * cc);
        out.I0 = L::select(series, two_h_e * s0, out.I0);
        out.J1 = L::select(series, two_h_e * hs * s1, out.J1);
        out.J2 = L::select(series, two_h_e * hs * hs * s2, out.J2);
    }
    return out;
}

// Gaussian Blending's transmittance per lane: a uniform window of total mass T (pixel area = 1) centred at
// (x, y) with side lengths (w, h) (paper §3.3). Initially the pixel itself.
template <class L>
struct WindowState {
    typename L::F T, x, y, w, h, C[3];
};

// `gaussian_blending`: blend one splat onto the window and replace the window by the uniform one
// with the same mass, mean and variance of T(x)(1 - alpha(x)) (eqs. 8-11, Appendix A), as the
// authors' renderCUDA does it (KERNELS.md §6.3), with the moments taken about the window centre (more accurate
// than the published float32 form, see window_side_moments): window sides go to the eigen-axis within 45 degrees,
// a window outside [0.1, 1e6] sigma falls back to scalar alpha at the window centre, and the pixel
// stops after adding a splat that leaves T < 1e-4. `took`, when given, receives the lanes whose window changed.
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_gaussian(const Splat2D& s, typename L::M live, WindowState<L>& win,
                                    typename L::M* took = nullptr) {
    using F = typename L::F;
    using M = typename L::M;
    const F dx = win.x - L::set(s.xy.x), dy = win.y - L::set(s.xy.y);
    const F half = L::set(0.5f), zero = L::set(0.0f);
    // Cheapest exact rejection first: the window (within half its perimeter of its centre) lies outside the splat's
    // bounding circle (radius >= the distance where its value falls below 1/256).
    const F reach = L::set(s.radius) + half * (win.w + win.h);
    M pass = L::and_not(live, dx * dx + dy * dy > reach * reach);
    GBV_TRACE(Tr, skip(L::and_not(live, pass), SKIP_RADIUS));
    if (!L::any(pass)) return L::none();
    const F u = dx * L::set(s.v1.x) + dy * L::set(s.v1.y);
    const F v = dx * L::set(-s.v1.y) + dy * L::set(s.v1.x);
    const bool aligned = fabsf(s.v1.x) > fabsf(s.v1.y);
    const F lu = aligned ? win.w : win.h;
    const F lv = aligned ? win.h : win.w;
    const F is1 = L::set(s.inv_sigma1), is2 = L::set(s.inv_sigma2);
    // The mean alpha over the window is at most the splat's largest value on it: skip before any erf when even
    // that is below 1/256 (log_min_alpha = ln(MIN_ALPHA_GB / opacity)). This also rejects every window lying
    // outside the published +-3.33 sigma box, whose edge value is exactly 1/256.
    const F gu = L::max(L::abs(u) - half * lu, zero) * is1;
    const F gv = L::max(L::abs(v) - half * lv, zero) * is2;
    pass = L::and_not(pass, L::set(-0.5f) * (gu * gu + gv * gv) < L::set(s.log_min_alpha));
    GBV_TRACE(Tr, skip(L::and_not(live, pass), SKIP_CUTOFF));
    if (!L::any(pass)) return L::none();

    const F U1 = (u - half * lu) * is1, U2 = (u + half * lu) * is1;
    const F V1 = (v - half * lv) * is2, V2 = (v + half * lv) * is2;
    const F wu_s = U2 - U1, wv_s = V2 - V1;  // window sides in sigma units
    const F lo = L::set(GB_MIN_UV_DIFF), hi = L::set(GB_MAX_UV_DIFF);
    const M normal = L::and_(L::and_(wu_s >= lo, wv_s >= lo), L::and_(wu_s <= hi, wv_s <= hi));
    M stop = L::none();
    const M fallback = L::and_not(pass, normal);
    if (L::any(fallback)) {
        // Stability fallback (Appendix B.1): scalar alpha at the window centre, window unchanged.
        GBV_TRACE(Tr, fallback(fallback));
        const F power = gaussian_power<L>(s, dx, dy);
        const M valid = L::and_(fallback, power <= zero);
        GBV_TRACE(Tr, skip(L::and_not(fallback, valid), SKIP_POWER));
        const F g = L::select(valid, L::exp(L::select(valid, power, zero)), zero);
        const F alpha = L::min(L::set(s.opacity) * g, L::set(MAX_ALPHA));
        GBV_TRACE(Tr, alpha(valid, alpha));
        const M take = L::and_not(fallback, alpha < L::set(MIN_ALPHA_GB));
        GBV_TRACE(Tr, skip(L::and_not(fallback, take), SKIP_ALPHA));
        const F w = win.T * alpha;
        GBV_TRACE(Tr, weight(take, w));
        for (int c = 0; c < 3; ++c) win.C[c] = L::select(take, win.C[c] + L::set(s.color[c]) * w, win.C[c]);
        win.T = L::select(take, win.T - w, win.T);
        stop = L::and_(take, win.T < L::set(T_STOP));
        if (took) *took = take;
    }
    const M inside = L::and_(pass, normal);
    if (!L::any(inside)) return stop;
    // Moments of T(x)(1 - alpha(x)) over the window (eqs. 10-11) about the window centre, in the splat's eigen-frame:
    // side integrals in sigma units (window_side_moments), scaled to pixels by sigma, sigma^2, sigma^3.
    const F s1 = L::set(s.sigma1), s2 = L::set(s.sigma2);
    const SideMoments<L> mu_ = window_side_moments<L>(u * is1, half * lu * is1, inside);
    const SideMoments<L> mv_ = window_side_moments<L>(v * is2, half * lv * is2, inside);
    const F i0u = s1 * mu_.I0, i0v = s2 * mv_.I0;
    const F inv_area = L::select(inside, L::set(1.0f) / (lu * lv), zero);
    const F o = L::set(s.opacity);
    const F alpha = L::min(o * i0u * i0v * inv_area, L::set(MAX_ALPHA));  // mean alpha over the window
    GBV_TRACE(Tr, alpha(inside, alpha));
    const M take = L::and_not(inside, alpha < L::set(MIN_ALPHA_GB));
    GBV_TRACE(Tr, skip(L::and_not(inside, take), SKIP_ALPHA));
    const F weight = win.T * alpha;  // eq. 9
    GBV_TRACE(Tr, weight(take, weight));
    for (int c = 0; c < 3; ++c) win.C[c] = L::select(take, win.C[c] + L::set(s.color[c]) * weight, win.C[c]);

    const F k = win.T * inv_area * o;
    const F twelfth = L::set(1.0f / 12.0f);
    const F m0 = win.T - weight;
    const F m1u = L::neg(k * (s1 * s1 * mu_.J1) * i0v), m1v = L::neg(k * i0u * (s2 * s2 * mv_.J1));
    const F m2u = win.T * lu * lu * twelfth - k * (s1 * s1 * s1 * mu_.J2) * i0v;
    const F m2v = win.T * lv * lv * twelfth - k * i0u * (s2 * s2 * s2 * mv_.J2);
    // eq. 11: the uniform window with the same mass, mean and variance; its centre moves by (du, dv)
    const F inv_m0 = L::set(1.0f) / m0;
    const F du = m1u * inv_m0, dv = m1v * inv_m0;
    const F min_var = L::set(GB_MIN_VAR), twelve = L::set(12.0f);
    const F wu = L::sqrt(twelve * L::max(m2u * inv_m0 - du * du, min_var));
    const F wv = L::sqrt(twelve * L::max(m2v * inv_m0 - dv * dv, min_var));
    win.T = L::select(take, m0, win.T);
    win.x = L::select(take, win.x + du * L::set(s.v1.x) + dv * L::set(-s.v1.y), win.x);
    win.y = L::select(take, win.y + du * L::set(s.v1.y) + dv * L::set(s.v1.x), win.y);
    win.w = L::select(take, aligned ? wu : wv, win.w);
    win.h = L::select(take, aligned ? wv : wu, win.h);
    if (took) *took = L::or_(*took, take);
    return L::or_(stop, L::and_(take, win.T < L::set(T_STOP)));
}

// ---- order-independent modes -----------------------------------------------------------------------------------

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

// `wsr`: sort-free weighted sum (KERNELS.md §7.2): alpha = o' exp(power), no 0.99 clamp, skipped below 1/255,
// C += c alpha, S += alpha; no transmittance and no early termination (never stops a lane). The weight alpha is
// capped at WSR_FIXED_MAX (the fixed-point bound; only huge trained view weights reach it) before it multiplies
// the colour, so a capped splat keeps its colour. The fixed-point sums are added lane by lane.
template <class L, class Tr = NoTrace>
GBV_HD void blend_wsr(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                      WsrSumsN<L::N>& acc) {
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

// Duplex-GS per-lane state (KERNELS.md §8.4): T = cummult, the product of (1 - alpha/E) over every splat blended
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

// ---- one pixel (CUDA's per-thread loop; the GLSL port has these names) ----------------------------------------------

// Pixel state of the one-pixel wrappers: scalar transmittance T and colour C, the Gaussian Blending window,
// the wsr sums, the duplex state.
struct TransmittanceWindow {
    float T;
    Vec2 xy;
    Vec2 wh;
};
struct WsrSums {
    int64_t C[3];
    int64_t S;
};
using DuplexState = DuplexLanes<Lanes1>;

// One pixel through blend_analytic (Analytic) or blend_scalar.
template <bool Analytic>
GBV_HD bool blend_alpha_pixel(const Splat2D& s, Vec2 pix, float& T, float C[3]) {
    AlphaState<Lanes1> st = {T, {C[0], C[1], C[2]}};
    const bool stop = Analytic ? blend_analytic<Lanes1>(s, pix.x, pix.y, true, st)
                               : blend_scalar<Lanes1>(s, pix.x, pix.y, true, st);
    T = st.T;
    for (int c = 0; c < 3; ++c) C[c] = st.C[c];
    return stop;
}

GBV_HD bool blend_scalar(const Splat2D& s, Vec2 pix, float& T, float C[3]) {
    return blend_alpha_pixel<false>(s, pix, T, C);
}

GBV_HD bool blend_analytic(const Splat2D& s, Vec2 pix, float& T, float C[3]) {
    return blend_alpha_pixel<true>(s, pix, T, C);
}

GBV_HD bool blend_gaussian(const Splat2D& s, TransmittanceWindow& win, float C[3]) {
    WindowState<Lanes1> st = {win.T, win.xy.x, win.xy.y, win.wh.x, win.wh.y, {C[0], C[1], C[2]}};
    const bool stop = blend_gaussian<Lanes1>(s, true, st);
    win = {st.T, {st.x, st.y}, {st.w, st.h}};
    for (int c = 0; c < 3; ++c) C[c] = st.C[c];
    return stop;
}

GBV_HD bool blend_wsr(const Splat2D& s, Vec2 pix, WsrSums& acc) {
    WsrSumsN<1> lane = {{{acc.C[0]}, {acc.C[1]}, {acc.C[2]}}, {acc.S}};
    blend_wsr<Lanes1>(s, pix.x, pix.y, true, lane);
    acc = {{lane.C[0][0], lane.C[1][0], lane.C[2][0]}, lane.S[0]};
    return false;
}

GBV_HD bool blend_duplex(const Splat2D& s, Vec2 pix, float et_grade, DuplexState& st) {
    return blend_duplex<Lanes1>(s, pix.x, pix.y, true, et_grade, st);
}

}  // namespace gbv
