// Per-pixel blending steps, one splat at a time, front to back, and the finishing of a pixel (resolve_pixel). Shared
// by every backend; the GLSL port (shaders/blend.glsl) keeps the one-pixel functions' names. The splat's Gaussian and
// its window moments are gaussian.h; the order-independent modes (wsr, duplex) are blend_oit.h.
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

#include "blend_oit.h"
#include "common.h"
#include "gaussian.h"
#include "lanes.h"
#include "trace.h"

namespace gbv {

// ---- scalar transmittance (scalar, mip, analytic) -----------------------------------------------------------------

template <class L>
struct AlphaState {
    typename L::F T, C[3];
};

// Scalar front-to-back compositing of one alpha per lane (3DGS renderCUDA, docs/modes.md#scalar): skip below
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

// Alpha at the pixel centre (eq. 5, clamped to MAX_ALPHA) on the lanes `pass` of `live` whose power is <= 0 and at
// least log_min_alpha = ln((1/255) / opacity) (below it alpha < 1/255: skipped before the exp). False when no lane
// passes (alpha not computed). The centre alpha of `scalar`, `mip` and the stochastic modes (stochastic.h).
template <class L, class Tr = NoTrace>
GBV_HD bool centre_alpha(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live, typename L::M& pass,
                         typename L::F& alpha) {
    using F = typename L::F;
    const F power = gaussian_power<L>(s, L::set(s.xy.x) - px, L::set(s.xy.y) - py);
    pass = L::and_(live, L::and_(power <= L::set(0.0f), power >= L::set(s.log_min_alpha)));
    GBV_TRACE(Tr, skip(L::and_not(live, power <= L::set(0.0f)), SKIP_POWER));
    GBV_TRACE(Tr, skip(L::and_not(live, pass), SKIP_CUTOFF));
    if (!L::any(pass)) return false;
    alpha = L::min(L::set(s.opacity) * L::exp(L::select(pass, power, L::set(0.0f))), L::set(MAX_ALPHA));
    return true;
}

// `scalar` and `mip`: alpha at the pixel centre, composited.
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_scalar(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                                  AlphaState<L>& st) {
    typename L::M pass;
    typename L::F alpha;
    if (!centre_alpha<L, Tr>(s, px, py, live, pass, alpha)) return L::none();
    return composite_scalar<L, Tr>(pass, alpha, s.color, st);
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

// Gaussian Blending's transmittance per lane: a uniform window of total mass T (pixel area = 1) centred at
// (x, y) with side lengths (w, h) (paper §3.3). Initially the pixel itself.
template <class L>
struct WindowState {
    typename L::F T, x, y, w, h, C[3];
};

// `gaussian_blending`: blend one splat onto the window and replace the window by the uniform one
// with the same mass, mean and variance of T(x)(1 - alpha(x)) (eqs. 8-11, Appendix A), as the
// authors' renderCUDA does it (docs/modes.md#gaussian-blending), with the moments taken about the window centre (more
// accurate than the published float32 form, see window_side_moments): window sides go to the eigen-axis within 45
// degrees, a window outside [0.1, 1e6] sigma falls back to scalar alpha at the window centre, and the pixel stops after
// adding a splat that leaves T < 1e-4. `took`, when given, receives the lanes whose window changed.
// Fast: the `fast` precision (RenderSettings.precision): shorter series and one exp for both sides' factors
// (window_side_moments), within the error bound tests/render/test_gb_fast.py asserts; every test and branch is the
// exact path's.
template <class L, class Tr = NoTrace, bool Fast = false>
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
    const F cu = u * is1, hu = half * lu * is1, cv = v * is2, hv = half * lv * is2;
    const SideMoments<L> mu_ = window_side_moments<L, Fast>(cu, hu, inside);
    const SideMoments<L> mv_ = window_side_moments<L, Fast>(cv, hv, inside);
    const F i0u = s1 * mu_.I0, i0v = s2 * mv_.I0;
    const F inv_area = L::select(inside, L::set(1.0f) / (lu * lv), zero);
    F o = L::set(s.opacity);
    if constexpr (Fast) {  // the series sides' factors e(c) (window_side_moments), in one exp
        const F series = L::set(GB_SERIES_MAX_HALF_WIDTH);
        const F q = L::select(L::and_(inside, hu <= series), cu * cu, zero) +
                    L::select(L::and_(inside, hv <= series), cv * cv, zero);
        o = o * L::exp(L::set(-0.5f) * q);
    }
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

// ---- finishing a pixel ---------------------------------------------------------------------------------------------

// A pixel's sums at the end of its list, in every mode: colour C, transmittance T (scalar, mip, analytic: T;
// gaussian_blending: the window's mass; wsr: 1, LC-WSR's background transmittance; duplex: the final cummult) and
// the weight sum S (wsr, duplex; unused otherwise).
struct PixelSums {
    float C[3];
    float T;
    float S;
};

// wsr's fixed-point sums of one pixel (WsrSumsN) as PixelSums.
GBV_HD PixelSums wsr_pixel_sums(const int64_t C[3], int64_t S) {
    const float inv = 1.0f / WSR_FIXED_SCALE;
    return {{(float)C[0] * inv, (float)C[1] * inv, (float)C[2] * inv}, 1.0f, (float)S * inv};
}

// Finish a pixel over the background bg: wsr and duplex divide their sums by the total weight (resolve_weighted;
// duplex gives the background no weight once its cummult is below DUPLEX_T_STOP), then rgb = C + T bg and
// alpha = 1 - T. Returns the total the sums were divided by (1 in the other modes).
GBV_HD float resolve_pixel(Mode mode, const PixelSums& p, float weight_background, const float bg[3], float rgb[3],
                           float* alpha) {
    float C[3] = {p.C[0], p.C[1], p.C[2]}, T = p.T, total = 1.0f;
    if (mode == WSR || mode == DUPLEX) {
        const float wbg = mode == DUPLEX && p.T < DUPLEX_T_STOP ? 0.0f : weight_background;
        total = resolve_weighted(p.C, p.S, wbg, p.T, C, &T);
    }
    for (int c = 0; c < 3; ++c) rgb[c] = C[c] + T * bg[c];
    *alpha = 1.0f - T;
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
    const bool stop =
        Analytic ? blend_analytic<Lanes1>(s, pix.x, pix.y, true, st) : blend_scalar<Lanes1>(s, pix.x, pix.y, true, st);
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

// fast: the `fast` precision (blend_gaussian's Fast); kernels pass a compile-time constant, which the compiler folds.
GBV_HD bool blend_gaussian(const Splat2D& s, TransmittanceWindow& win, float C[3], bool fast = false) {
    WindowState<Lanes1> st = {win.T, win.xy.x, win.xy.y, win.wh.x, win.wh.y, {C[0], C[1], C[2]}};
    const bool stop = fast ? blend_gaussian<Lanes1, NoTrace, true>(s, true, st) : blend_gaussian<Lanes1>(s, true, st);
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
