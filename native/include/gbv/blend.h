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

// Result of blending one pixel (or sub-pixel sample).
struct PixelOut {
    float C[3];
    float T;         // final transmittance
    int32_t evals;   // splats evaluated
    Vec2 window;     // final window size (gaussian_blending only)
};

// Blend the depth-sorted splats `list[0..n)` at pixel centre `pix` in `mode`.
template <typename SplatAt>
GBV_HD PixelOut blend_pixel(Mode mode, Vec2 pix, int n, SplatAt splat_at) {
    PixelOut o = {{0.0f, 0.0f, 0.0f}, 1.0f, 0, {1.0f, 1.0f}};
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
