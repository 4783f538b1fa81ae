// GLSL port of native/include/gbv/blend.h, function by function with the same names and constants.
// Per-pixel blending steps, one splat at a time, front to back. Each step returns true once the pixel is
// finished (early termination). Needs common.glsl and mathf.glsl. The per-pixel loop (blend_pixel in C++) is the
// batch loop of blend.comp, which walks a tile's depth-sorted list through shared memory.

// Scalar front-to-back compositing of one alpha (3DGS renderCUDA, KERNELS.md §0.7): skip below min_alpha; stop
// without adding the splat when T(1 - alpha) < 1e-4.
bool composite_scalar(float alpha, vec3 color, inout float T, inout vec3 C) {
    if (alpha < MIN_ALPHA_3DGS) return false;
    const float test_T = T * (1.0 - alpha);
    if (test_T < T_STOP) return true;
    const float w = alpha * T;
    C[0] += color[0] * w;
    C[1] += color[1] * w;
    C[2] += color[2] * w;
    T = test_T;
    return false;
}

// Gaussian value exp(power) at offset d = xy - p, or 0 when power > 0 (numerically invalid) or NaN (the blend
// steps' NaN rule, blend.h).
float gaussian_at(Splat2D s, vec2 d) {
    const float power = -0.5 * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    return power <= 0.0 ? expf(power) : 0.0;
}

// `scalar` and `mip`: alpha at the pixel centre (eq. 5). Offsets whose power is below
// log_min_alpha = ln((1/255) / opacity) would give alpha < 1/255 and are skipped before the exp.
bool blend_scalar(Splat2D s, vec2 pix, inout float T, inout vec3 C) {
    const vec2 d = s.xy - pix;
    const float power = -0.5 * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects (blend.h)
    const float alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    return composite_scalar(alpha, s.color, T, C);
}

// Analytic-Splatting's logistic approximation of the standard normal CDF (KERNELS.md §4): sigmoid(1.6x + 0.07x^3).
float approx_cdf(float x) { return 1.0 / (1.0 + expf(-(1.6 * x + 0.07 * x * x * x))); }

// `analytic`: mean alpha over the unit pixel, separable in the splat's eigen-frame (Analytic-Splatting).
bool blend_analytic(Splat2D s, vec2 pix, inout float T, inout vec3 C) {
    const vec2 d = pix - s.xy;
    const vec2 v2 = vec2(-s.v1.y, s.v1.x);
    const float u = dot(d, s.v1), v = dot(d, v2);
    const float iu = s.sigma1 * (approx_cdf((u + 0.5) / s.sigma1) - approx_cdf((u - 0.5) / s.sigma1));
    const float iv = s.sigma2 * (approx_cdf((v + 0.5) / s.sigma2) - approx_cdf((v - 0.5) / s.sigma2));
    const float alpha = minf(s.opacity * TWO_PI * iu * iv, MAX_ALPHA);
    return composite_scalar(alpha, s.color, T, C);
}

// Zeroth moment of exp(-t^2/2) from 0 to x (paper eq. 13 with sigma = 1), sqrt(pi/2) erf(x/sqrt(2)), given
// e = exp(-x^2/2). erf uses Abramowitz & Stegun 7.1.26 (absolute error < 1.5e-7, about float32 rounding),
// whose exp(-z^2) is that same e: one exp per window edge serves all three moments, and every backend
// (GLSL has no erf) computes the identical function. The first and second moments over [a, b] follow from
// e: I1 = e(a) - e(b), I2 = I0 + a e(a) - b e(b).
float gaussian_moment0(float x, float e) {
    const float z = abs(x) * 0.7071067811865476;
    const float t = 1.0 / (1.0 + 0.3275911 * z);
    const float poly =
        t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    const float erf_abs = 1.0 - poly * e;
    return SQRT_PI_2 * (x < 0.0 ? -erf_abs : erf_abs);
}

// Moments of exp(-t^2/2) over one window side [c - h, c + h] (splat sigma units) about the window centre c:
// I0 = int e, J1 = int (t - c) e, J2 = int (t - c)^2 e. Hermite series of e(c + s) for h <= 1, the closed form
// about the centre above that (port of blend.h's window_side_moments, which says why).
struct SideMoments {
    float I0;
    float J1;
    float J2;
};

SideMoments window_side_moments(float c, float h) {
    if (h > GB_SERIES_MAX_HALF_WIDTH) {
        const float a = c - h, b = c + h;
        const float ea = expf(-0.5 * a * a), eb = expf(-0.5 * b * b);
        const float I0 = gaussian_moment0(b, eb) - gaussian_moment0(a, ea);
        const float J1 = (ea - eb) - c * I0;
        return SideMoments(I0, J1, I0 - h * (ea + eb) - c * J1);
    }
    float he_prev = 1.0, he = c, p = h;  // He_{n-1}, He_n, h^n/n! at n = 1
    float s0 = 1.0, s1 = -(p * he) * (1.0 / 3.0), s2 = 1.0 / 3.0;
    // Every term, unlike blend.h (which stops at 6 or 10 for narrower windows; the sums agree to ~1e-7): a loop with
    // a data-dependent bound is not unrolled and would count towards llvmpipe's loop cap (see gbviewer/render/glsl/limits.py).
    for (int n = 2; n <= GB_SERIES_TERMS; ++n) {
        const float he_next = c * he - float(n - 1) * he_prev;
        he_prev = he;
        he = he_next;
        p = p * h * (1.0 / float(n));
        if (n % 2 == 0) {
            const float b = p * he;
            s0 = s0 + b * (1.0 / float(n + 1));
            s2 = s2 + b * (1.0 / float(n + 3));
        } else {
            s1 = s1 - p * he * (1.0 / float(n + 2));
        }
    }
    const float two_h_e = 2.0 * h * expf(-0.5 * c * c);
    return SideMoments(two_h_e * s0, two_h_e * h * s1, two_h_e * h * h * s2);
}

// Gaussian Blending's transmittance: a uniform window of total mass T (pixel area = 1) centred at xy with side
// lengths wh (paper §3.3). Initially the pixel itself.
struct TransmittanceWindow {
    float T;
    vec2 xy;
    vec2 wh;
};

// `gaussian_blending`: blend one splat onto the window and replace the window by the uniform one with the same
// mass, mean and variance of T(x)(1 - alpha(x)) (eqs. 8-11, Appendix A), as the authors' renderCUDA does it
// (KERNELS.md §6.3), with the moments taken about the window centre (window_side_moments): window sides go to the
// eigen-axis within 45 degrees, a window outside [0.1, 1e6] sigma falls back to scalar alpha at the window centre,
// and the pixel stops after adding a splat that leaves T < 1e-4.
bool blend_gaussian(Splat2D s, inout TransmittanceWindow win, inout vec3 C) {
    const vec2 d = win.xy - s.xy;
    // Cheapest exact rejection first: the window (within half its perimeter of its centre) lies outside the splat's
    // bounding circle (radius >= the distance where its value falls below 1/256).
    const float reach = s.radius + 0.5 * (win.wh.x + win.wh.y);
    if (dot(d, d) > reach * reach) return false;
    const vec2 v2 = vec2(-s.v1.y, s.v1.x);
    const float u = dot(d, s.v1), v = dot(d, v2);
    const bool aligned = abs(s.v1.x) > abs(s.v1.y);
    const float lu = aligned ? win.wh.x : win.wh.y;
    const float lv = aligned ? win.wh.y : win.wh.x;
    // The mean alpha over the window is at most the splat's largest value on it: skip before any erf when even
    // that is below 1/256 (log_min_alpha = ln(MIN_ALPHA_GB / opacity)). This also rejects every window lying
    // outside the published +-3.33 sigma box, whose edge value is exactly 1/256.
    const float gu = maxf(abs(u) - 0.5 * lu, 0.0) * s.inv_sigma1;
    const float gv = maxf(abs(v) - 0.5 * lv, 0.0) * s.inv_sigma2;
    if (-0.5 * (gu * gu + gv * gv) < s.log_min_alpha) return false;

    const float U1 = (u - 0.5 * lu) * s.inv_sigma1, U2 = (u + 0.5 * lu) * s.inv_sigma1;
    const float V1 = (v - 0.5 * lv) * s.inv_sigma2, V2 = (v + 0.5 * lv) * s.inv_sigma2;
    const float wu_s = U2 - U1, wv_s = V2 - V1;  // window sides in sigma units
    if (!(wu_s >= GB_MIN_UV_DIFF && wv_s >= GB_MIN_UV_DIFF && wu_s <= GB_MAX_UV_DIFF && wv_s <= GB_MAX_UV_DIFF)) {
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
    // Moments of T(x)(1 - alpha(x)) about the window centre (eqs. 10-11), as blend.h computes them.
    const SideMoments mu_ = window_side_moments(u * s.inv_sigma1, 0.5 * lu * s.inv_sigma1);
    const SideMoments mv_ = window_side_moments(v * s.inv_sigma2, 0.5 * lv * s.inv_sigma2);
    const float i0u = s.sigma1 * mu_.I0, i0v = s.sigma2 * mv_.I0;
    const float inv_area = 1.0 / (lu * lv);
    const float alpha = minf(s.opacity * i0u * i0v * inv_area, MAX_ALPHA);  // mean alpha over the window
    if (alpha < MIN_ALPHA_GB) return false;
    const float weight = win.T * alpha;  // eq. 9
    C[0] += s.color[0] * weight;
    C[1] += s.color[1] * weight;
    C[2] += s.color[2] * weight;

    const float k = win.T * inv_area * s.opacity;
    const float m0 = win.T - weight;
    const float m1u = -(k * (s.sigma1 * s.sigma1 * mu_.J1) * i0v), m1v = -(k * i0u * (s.sigma2 * s.sigma2 * mv_.J1));
    const float m2u = win.T * lu * lu * (1.0 / 12.0) - k * (s.sigma1 * s.sigma1 * s.sigma1 * mu_.J2) * i0v;
    const float m2v = win.T * lv * lv * (1.0 / 12.0) - k * i0u * (s.sigma2 * s.sigma2 * s.sigma2 * mv_.J2);
    // eq. 11: the uniform window with the same mass, mean and variance; its centre moves by (du, dv)
    const float inv_m0 = 1.0 / m0;
    const float du = m1u * inv_m0, dv = m1v * inv_m0;
    const float var_u = maxf(m2u * inv_m0 - du * du, GB_MIN_VAR), var_v = maxf(m2v * inv_m0 - dv * dv, GB_MIN_VAR);
    win.T = m0;
    win.xy = win.xy + du * s.v1 + dv * v2;
    const float wu = sqrt(12.0 * var_u), wv = sqrt(12.0 * var_v);
    win.wh = aligned ? vec2(wu, wv) : vec2(wv, wu);
    return win.T < T_STOP;
}

// ---- order-independent modes ------------------------------------------------------------------------------------

// LC-WSR sums for one pixel. The C++ keeps them in 64-bit fixed point (bitwise order independent); GLSL 4.30 core
// has no 64-bit integers, so here they are float sums in tile-list order (splat-index order). The terms get the
// C++'s clamps (to_fixed, blend_wsr) so that both backends weigh huge trained view weights alike.
struct WsrSums {
    vec3 C;
    float S;
};

// `wsr`: sort-free weighted sum (KERNELS.md §7.2): alpha = o' exp(power), no 0.99 clamp, skipped below 1/255,
// C += c alpha, S += alpha; no transmittance and no early termination (never returns true). alpha and each term
// are capped at WSR_FIXED_MAX, as in blend.h.
bool blend_wsr(Splat2D s, vec2 pix, inout WsrSums acc) {
    const vec2 d = s.xy - pix;
    const float power = -0.5 * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects (blend.h)
    const float alpha = minf(s.opacity * expf(power), WSR_FIXED_MAX);
    if (alpha < MIN_ALPHA_3DGS) return false;
    acc.C[0] += minf(s.color[0] * alpha, WSR_FIXED_MAX);
    acc.C[1] += minf(s.color[1] * alpha, WSR_FIXED_MAX);
    acc.C[2] += minf(s.color[2] * alpha, WSR_FIXED_MAX);
    acc.S += alpha;
    return false;
}

// Duplex-GS per-pixel state (KERNELS.md §8.4): T = cummult, T_cell = T when the current cell was entered, the sums.
struct DuplexState {
    float T;
    float T_cell;
    int cell;
    float S;
    vec3 C;
};

// `duplex`: one splat of a cell-sorted list; see blend.h.
bool blend_duplex(Splat2D s, vec2 pix, float et_grade, inout DuplexState st) {
    const vec2 d = s.xy - pix;
    if (d.x * d.x + d.y * d.y > s.radius * s.radius) return false;
    const float power = -0.5 * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects (blend.h)
    float alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    if (alpha < MIN_ALPHA_3DGS) return false;
    if (s.cell != st.cell) {
        if (st.T < DUPLEX_T_STOP) return true;
        st.cell = s.cell;
        st.T_cell = st.T;
    }
    alpha = alpha / et_grade;
    st.T *= 1.0 - alpha;
    const float w = alpha * st.T_cell;
    st.C[0] += s.color[0] * w;
    st.C[1] += s.color[1] * w;
    st.C[2] += s.color[2] * w;
    st.S += w;
    return false;
}

// out = (C + bg w_bg) / (S + w_bg T_bg) as C' + T' bg: C' = C / total, T' = w_bg / total (see blend.h).
void resolve_weighted(vec3 C, float S, float wbg, float T_bg, out vec3 out_C, out float out_T) {
    float total = S + wbg * T_bg;
    if (total == 0.0) total = WSR_EMPTY_SUM;
    for (int c = 0; c < 3; ++c) out_C[c] = C[c] / total;
    out_T = wbg / total;
}
