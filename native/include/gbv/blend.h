// Per-pixel blending steps, one splat at a time, front to back. Each step returns true once the pixel
// is finished (early termination). Shared by every backend; the GLSL port keeps the same names.
#pragma once

#include "common.h"

namespace gbv {

// Scalar front-to-back compositing of one alpha (3DGS renderCUDA, KERNELS.md §0.7): skip below
// min_alpha; stop without adding the splat when T(1 - alpha) < 1e-4.
GBV_HD bool composite_scalar(float alpha, const float color[3], float& T, float C[3]) {
    if (alpha < MIN_ALPHA_3DGS) return false;
    const float test_T = T * (1.0f - alpha);
    if (test_T < T_STOP) return true;
    const float w = alpha * T;
    C[0] += color[0] * w;
    C[1] += color[1] * w;
    C[2] += color[2] * w;
    T = test_T;
    return false;
}

// Gaussian value exp(power) at offset d = xy - p, or 0 when power > 0 (numerically invalid).
GBV_HD float gaussian_at(const Splat2D& s, Vec2 d) {
    const float power = -0.5f * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    return power > 0.0f ? 0.0f : expf(power);
}

// `scalar` and `mip`: alpha at the pixel centre (eq. 5). Offsets whose power is below
// log_min_alpha = ln((1/255) / opacity) would give alpha < 1/255 and are skipped before the exp.
GBV_HD bool blend_scalar(const Splat2D& s, Vec2 pix, float& T, float C[3]) {
    const Vec2 d = s.xy - pix;
    const float power = -0.5f * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (power > 0.0f || power < s.log_min_alpha) return false;
    const float alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    return composite_scalar(alpha, s.color, T, C);
}

// Analytic-Splatting's logistic approximation of the standard normal CDF (KERNELS.md §4):
// sigmoid(1.6x + 0.07x^3), written with expf (the published 0.5 tanh(z/2) + 0.5 is the same function).
GBV_HD float approx_cdf(float x) { return 1.0f / (1.0f + expf(-(1.6f * x + 0.07f * x * x * x))); }

// `analytic`: mean alpha over the unit pixel, separable in the splat's eigen-frame (Analytic-Splatting).
GBV_HD bool blend_analytic(const Splat2D& s, Vec2 pix, float& T, float C[3]) {
    const Vec2 d = pix - s.xy;
    const Vec2 v2 = {-s.v1.y, s.v1.x};
    const float u = dot(d, s.v1), v = dot(d, v2);
    const float iu = s.sigma1 * (approx_cdf((u + 0.5f) / s.sigma1) - approx_cdf((u - 0.5f) / s.sigma1));
    const float iv = s.sigma2 * (approx_cdf((v + 0.5f) / s.sigma2) - approx_cdf((v - 0.5f) / s.sigma2));
    const float alpha = minf(s.opacity * TWO_PI * iu * iv, MAX_ALPHA);
    return composite_scalar(alpha, s.color, T, C);
}

// Zeroth moment of exp(-t^2/2) from 0 to x (paper eq. 13 with sigma = 1), sqrt(pi/2) erf(x/sqrt(2)), given
// e = exp(-x^2/2). erf uses Abramowitz & Stegun 7.1.26 (absolute error < 1.5e-7, about float32 rounding),
// whose exp(-z^2) is that same e: one exp per window edge serves all three moments, and every backend
// (GLSL has no erf) computes the identical function. The first and second moments over [a, b] follow from
// e: I1 = e(a) - e(b), I2 = I0 + a e(a) - b e(b).
GBV_HD float gaussian_moment0(float x, float e) {
    const float z = fabsf(x) * 0.7071067811865476f;
    const float t = 1.0f / (1.0f + 0.3275911f * z);
    const float poly = t * (0.254829592f + t * (-0.284496736f + t * (1.421413741f + t * (-1.453152027f + t * 1.061405429f))));
    const float erf_abs = 1.0f - poly * e;
    return SQRT_PI_2 * (x < 0.0f ? -erf_abs : erf_abs);
}

// Gaussian Blending's transmittance: a uniform window of total mass T (pixel area = 1) centred at xy
// with side lengths wh (paper §3.3). Initially the pixel itself.
struct TransmittanceWindow {
    float T;
    Vec2 xy;
    Vec2 wh;
};

// `gaussian_blending`: blend one splat onto the window and replace the window by the uniform one
// with the same mass, mean and variance of T(x)(1 - alpha(x)) (eqs. 8-11, Appendix A), as the
// authors' renderCUDA does it (KERNELS.md §6.3): window sides go to the eigen-axis within 45 degrees,
// a window outside [0.1, 1e6] sigma falls back to scalar alpha at the window centre, and the pixel
// stops after adding a splat that leaves T < 1e-4.
GBV_HD bool blend_gaussian(const Splat2D& s, TransmittanceWindow& win, float C[3]) {
    const Vec2 d = win.xy - s.xy;
    // Cheapest exact rejection first: the window (within half its perimeter of its centre) lies outside the splat's
    // bounding circle (radius >= the distance where its value falls below 1/256).
    const float reach = s.radius + 0.5f * (win.wh.x + win.wh.y);
    if (dot(d, d) > reach * reach) return false;
    const Vec2 v2 = {-s.v1.y, s.v1.x};
    const float u = dot(d, s.v1), v = dot(d, v2);
    const bool aligned = fabsf(s.v1.x) > fabsf(s.v1.y);
    const float lu = aligned ? win.wh.x : win.wh.y;
    const float lv = aligned ? win.wh.y : win.wh.x;
    // The mean alpha over the window is at most the splat's largest value on it: skip before any erf when even
    // that is below 1/256 (log_min_alpha = ln(MIN_ALPHA_GB / opacity)). This also rejects every window lying
    // outside the published +-3.33 sigma box, whose edge value is exactly 1/256.
    const float gu = maxf(fabsf(u) - 0.5f * lu, 0.0f) * s.inv_sigma1;
    const float gv = maxf(fabsf(v) - 0.5f * lv, 0.0f) * s.inv_sigma2;
    if (-0.5f * (gu * gu + gv * gv) < s.log_min_alpha) return false;

    const float U1 = (u - 0.5f * lu) * s.inv_sigma1, U2 = (u + 0.5f * lu) * s.inv_sigma1;
    const float V1 = (v - 0.5f * lv) * s.inv_sigma2, V2 = (v + 0.5f * lv) * s.inv_sigma2;
    const float du = U2 - U1, dv = V2 - V1;
    if (!(du >= GB_MIN_UV_DIFF && dv >= GB_MIN_UV_DIFF && du <= GB_MAX_UV_DIFF && dv <= GB_MAX_UV_DIFF)) {
        // Stability fallback (Appendix B.1): scalar alpha at the window centre, window unchanged.
        const float alpha = minf(s.opacity * gaussian_at(s, d), MAX_ALPHA);
        if (alpha < MIN_ALPHA_GB) return false;
        const float w = win.T * alpha;
        C[0] += s.color[0] * w;
        C[1] += s.color[1] * w;
        C[2] += s.color[2] * w;
        win.T -= w;
        return win.T < T_STOP;
    }
    const float eU1 = expf(-0.5f * U1 * U1), eU2 = expf(-0.5f * U2 * U2);
    const float eV1 = expf(-0.5f * V1 * V1), eV2 = expf(-0.5f * V2 * V2);
    const float i0u = s.sigma1 * (gaussian_moment0(U2, eU2) - gaussian_moment0(U1, eU1));
    const float i0v = s.sigma2 * (gaussian_moment0(V2, eV2) - gaussian_moment0(V1, eV1));
    const float inv_area = 1.0f / (lu * lv);
    const float alpha = minf(s.opacity * i0u * i0v * inv_area, MAX_ALPHA);  // mean alpha over the window
    if (alpha < MIN_ALPHA_GB) return false;
    const float weight = win.T * alpha;  // eq. 9
    C[0] += s.color[0] * weight;
    C[1] += s.color[1] * weight;
    C[2] += s.color[2] * weight;

    const float s1sq = s.sigma1 * s.sigma1, s2sq = s.sigma2 * s.sigma2;
    const float i1u = s1sq * (eU1 - eU2), i1v = s2sq * (eV1 - eV2);
    const float i2u = s1sq * (i0u + s.sigma1 * (U1 * eU1 - U2 * eU2));
    const float i2v = s2sq * (i0v + s.sigma2 * (V1 * eV1 - V2 * eV2));
    const float k = win.T * inv_area * s.opacity;
    // eq. 10: moments of T(x)(1 - alpha(x)) over the window, in the splat's eigen-frame
    const float m0 = win.T - weight;
    const float m1u = win.T * u - k * i1u * i0v, m1v = win.T * v - k * i0u * i1v;
    const float m2u = win.T * (u * u + lu * lu / 12.0f) - k * i2u * i0v;
    const float m2v = win.T * (v * v + lv * lv / 12.0f) - k * i0u * i2v;
    // eq. 11: the uniform window with the same mass, mean and variance
    const float inv_m0 = 1.0f / m0;
    const float mu = m1u * inv_m0, mv = m1v * inv_m0;
    const float var_u = maxf(m2u * inv_m0 - mu * mu, GB_MIN_VAR), var_v = maxf(m2v * inv_m0 - mv * mv, GB_MIN_VAR);
    win.T = m0;
    win.xy = s.xy + mu * s.v1 + mv * v2;
    const float wu = sqrtf(12.0f * var_u), wv = sqrtf(12.0f * var_v);
    win.wh = aligned ? Vec2{wu, wv} : Vec2{wv, wu};
    return win.T < T_STOP;
}

// ---- order-independent modes -----------------------------------------------------------------------------------

// LC-WSR sums for one pixel: sum of alpha_i c_i and of alpha_i, in 64-bit fixed point with 2^-36 resolution.
// Integer addition is associative, so the sums (and the pixel) are bitwise the same for any order of the
// splats: the CPU's tile lists stay in splat-index order, unsorted, and still give a permutation-invariant
// image. Each float term is rounded once to the fixed-point grid (absolute error <= 2^-37 per term, ~1e-7 after
// 10^4 terms, far below float32 rounding of the final quotient). The GLSL port accumulates in float.
struct WsrSums {
    int64_t C[3];
    int64_t S;
};

// A non-negative float on the fixed-point grid. Terms are clamped to WSR_FIXED_MAX = 2^6, 2^42 on the grid, so
// that a sum of up to 2^21 - 1 terms (2M splats at one pixel) stays below 2^63: no signed overflow.
GBV_HD int64_t to_fixed(float x) { return (int64_t)rintf(minf(x, WSR_FIXED_MAX) * WSR_FIXED_SCALE); }

// `wsr`: sort-free weighted sum (KERNELS.md §7.2): alpha = o' exp(power), no 0.99 clamp, skipped below 1/255,
// C += c alpha, S += alpha; no transmittance and no early termination (never returns true). The weight alpha is
// capped at WSR_FIXED_MAX (the fixed-point bound; only huge trained view weights reach it) before it multiplies
// the colour, so a capped splat keeps its colour.
GBV_HD bool blend_wsr(const Splat2D& s, Vec2 pix, WsrSums& acc) {
    const Vec2 d = s.xy - pix;
    const float power = -0.5f * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (power > 0.0f || power < s.log_min_alpha) return false;
    const float alpha = minf(s.opacity * expf(power), WSR_FIXED_MAX);
    if (alpha < MIN_ALPHA_3DGS) return false;
    acc.C[0] += to_fixed(s.color[0] * alpha);
    acc.C[1] += to_fixed(s.color[1] * alpha);
    acc.C[2] += to_fixed(s.color[2] * alpha);
    acc.S += to_fixed(alpha);
    return false;
}

// Duplex-GS per-pixel state (KERNELS.md §8.4): T = cummult, the product of (1 - alpha/E) over every splat blended
// so far; T_cell = T when the current cell was entered (anchor_correct); the weighted sums C and S.
struct DuplexState {
    float T;
    float T_cell;
    int32_t cell;
    float S;
    float C[3];
};

// `duplex`: one splat of a cell-sorted list (cells front to back, a cell's splats in any order). Pixels outside
// the splat's radius are skipped (False Positive Skip); alpha = min(o' exp(power), 0.99), skipped below 1/255. On
// entering a new cell the pixel stops when T < 0.01, else T_cell = T. Then alpha /= E, T *= 1 - alpha, and the
// splat adds with weight alpha T_cell. Inside a cell every weight uses the same T_cell: the cell's sum does not
// depend on the order of its splats (only the float rounding of T does).
GBV_HD bool blend_duplex(const Splat2D& s, Vec2 pix, float et_grade, DuplexState& st) {
    const Vec2 d = s.xy - pix;
    if (d.x * d.x + d.y * d.y > s.radius * s.radius) return false;
    const float power = -0.5f * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (power > 0.0f || power < s.log_min_alpha) return false;
    float alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    if (alpha < MIN_ALPHA_3DGS) return false;
    if (s.cell != st.cell) {
        if (st.T < DUPLEX_T_STOP) return true;
        st.cell = s.cell;
        st.T_cell = st.T;
    }
    alpha = alpha / et_grade;
    st.T *= 1.0f - alpha;
    const float w = alpha * st.T_cell;
    st.C[0] += s.color[0] * w;
    st.C[1] += s.color[1] * w;
    st.C[2] += s.color[2] * w;
    st.S += w;
    return false;
}

// The published normalisation out = (C + bg w_bg) / (S + w_bg T_bg), written as out = C' + T' bg with
// C' = C / S_total and T' = w_bg / S_total (the background's share of the weights; Frame.alpha = 1 - T'). wsr:
// T_bg = 1; duplex: T_bg = the final cummult, and w_bg = 0 once it is below 0.01. A total of exactly 0 becomes
// 1e-4 (LC-WSR; duplex does the same here instead of dividing by zero).
GBV_HD void resolve_weighted(const float C[3], float S, float wbg, float T_bg, float out_C[3], float* out_T) {
    float total = S + wbg * T_bg;
    if (total == 0.0f) total = WSR_EMPTY_SUM;
    for (int c = 0; c < 3; ++c) out_C[c] = C[c] / total;
    *out_T = wbg / total;
}

// Result of blending one pixel (or sub-pixel sample).
struct PixelOut {
    float C[3];
    float T;         // final transmittance
    int32_t evals;   // splats evaluated
    Vec2 window;     // final window size (gaussian_blending only)
};

// Blend the splats `list[0..n)` at pixel centre `pix` in `mode`: depth-sorted for the alpha-blending modes, in
// any order for wsr, cell-sorted for duplex. The output is C + T bg in every mode (see resolve_weighted).
template <typename SplatAt>
GBV_HD PixelOut blend_pixel(Mode mode, Vec2 pix, int n, SplatAt splat_at, const OitParams& oit) {
    PixelOut o = {{0.0f, 0.0f, 0.0f}, 1.0f, 0, {1.0f, 1.0f}};
    if (mode == WSR) {
        WsrSums acc = {{0, 0, 0}, 0};
        for (int i = 0; i < n; ++i) blend_wsr(splat_at(i), pix, acc);
        const float C[3] = {(float)acc.C[0] * (1.0f / WSR_FIXED_SCALE), (float)acc.C[1] * (1.0f / WSR_FIXED_SCALE),
                            (float)acc.C[2] * (1.0f / WSR_FIXED_SCALE)};
        resolve_weighted(C, (float)acc.S * (1.0f / WSR_FIXED_SCALE), oit.weight_background, 1.0f, o.C, &o.T);
        o.evals = n;
        return o;
    }
    if (mode == DUPLEX) {
        DuplexState st = {1.0f, 1.0f, -1, 0.0f, {0.0f, 0.0f, 0.0f}};
        int i = 0;
        while (i < n && !blend_duplex(splat_at(i), pix, oit.et_grade, st)) ++i;
        o.evals = i < n ? i + 1 : n;
        const float wbg = st.T < DUPLEX_T_STOP ? 0.0f : oit.weight_background;
        resolve_weighted(st.C, st.S, wbg, st.T, o.C, &o.T);
        return o;
    }
    if (mode == GAUSSIAN_BLENDING) {
        TransmittanceWindow win = {1.0f, pix, {1.0f, 1.0f}};
        int i = 0;
        while (i < n && !blend_gaussian(splat_at(i), win, o.C)) ++i;
        o.evals = i < n ? i + 1 : n;
        o.T = win.T;
        o.window = win.wh;
        return o;
    }
    int i = 0;
    if (mode == ANALYTIC) {
        while (i < n && !blend_analytic(splat_at(i), pix, o.T, o.C)) ++i;
    } else {
        while (i < n && !blend_scalar(splat_at(i), pix, o.T, o.C)) ++i;
    }
    o.evals = i < n ? i + 1 : n;
    return o;
}

}  // namespace gbv
