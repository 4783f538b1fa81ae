// GLSL port of the one-pixel blending of native/include/gbv/blend.h, gaussian.h and blend_oit.h, function by function
// with the same names and constants; each function's C++ original (named in its comment) documents it, and the
// comments here say only where the port differs. A step returns true once the pixel is finished (early
// termination). Needs common.glsl and mathf.glsl. The per-pixel loop is the batch loop of blend.comp (CUDA's
// render_kernel, the CPU's blend_tile), which walks a tile's list through shared memory.

// port of blend.h: composite_scalar
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

// port of gaussian.h: gaussian_power (offset d, either sign)
float gaussian_power(Splat2D s, vec2 d) {
    return -0.5 * (s.conic[0] * d.x * d.x + s.conic[2] * d.y * d.y) - s.conic[1] * d.x * d.y;
}

// exp(gaussian_power), or 0 when the power is > 0 or NaN: the scalar fallback of blend.h's blend_gaussian.
float gaussian_at(Splat2D s, vec2 d) {
    const float power = gaussian_power(s, d);
    return power <= 0.0 ? expf(power) : 0.0;
}

// port of blend.h: centre_alpha (one pixel; false when the power test rejects it, alpha then unset)
bool centre_alpha(Splat2D s, vec2 pix, out float alpha) {
    const float power = gaussian_power(s, s.xy - pix);
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects
    alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    return true;
}

// port of blend.h: blend_scalar
bool blend_scalar(Splat2D s, vec2 pix, inout float T, inout vec3 C) {
    float alpha;
    if (!centre_alpha(s, pix, alpha)) return false;
    return composite_scalar(alpha, s.color, T, C);
}

// port of stochastic.h: hash32, the keys and the fragment's uniform
uint hash32(uint x) {
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}
uint stochastic_frame_key(uint seed, uint frame) { return hash32(hash32(seed ^ 0x9e3779b9u) ^ frame); }
uint stochastic_sample_key(uint frame_key, uint X, uint Y) { return hash32(hash32(frame_key ^ X) ^ Y); }
uint stochastic_splat_key(int id) { return hash32(uint(id) ^ 0x85ebca6bu); }
float stochastic_uniform(uint sample_key, uint splat_key) {
    return float(hash32(sample_key ^ splat_key) >> 8u) * (1.0 / 16777216.0);
}

// port of stochastic.h: stochastic_keep (one pixel, its sample key)
bool stochastic_keep(Splat2D s, vec2 pix, uint key) {
    float alpha;
    if (!centre_alpha(s, pix, alpha) || alpha < MIN_ALPHA_3DGS) return false;
    return stochastic_uniform(key, stochastic_splat_key(s.id)) < alpha;
}

// port of stochastic.h: blend_stochastic
bool blend_stochastic(Splat2D s, vec2 pix, uint key, inout float T, inout vec3 C) {
    if (!stochastic_keep(s, pix, key)) return false;
    C = s.color;
    T = 0.0;
    return true;
}

// port of stochastic.h: blend_stochastic_popfree (one pixel: T, the nearest kept fragment's depth key, C)
void blend_stochastic_popfree(Splat2D s, vec4 plane, vec2 pix, uint key, inout float T, inout float depth_key,
                              inout vec3 C) {
    if (!stochastic_keep(s, pix, key)) return;
    float k = (plane.x * pix.x + plane.y * pix.y + plane.z) / plane.w;
    if (isnan(k)) k = -3.402823466e38;  // a splat without a plane is behind every plane
    if (!(k > depth_key)) return;
    C = s.color;
    T = 0.0;
    depth_key = k;
}

// port of gaussian.h: approx_cdf
float approx_cdf(float x) { return 1.0 / (1.0 + expf(-(1.6 * x + 0.07 * x * x * x))); }

// port of blend.h: blend_analytic
bool blend_analytic(Splat2D s, vec2 pix, inout float T, inout vec3 C) {
    const vec2 d = pix - s.xy;
    const vec2 v2 = vec2(-s.v1.y, s.v1.x);
    const float u = dot(d, s.v1), v = dot(d, v2);
    const float iu = s.sigma1 * (approx_cdf((u + 0.5) / s.sigma1) - approx_cdf((u - 0.5) / s.sigma1));
    const float iv = s.sigma2 * (approx_cdf((v + 0.5) / s.sigma2) - approx_cdf((v - 0.5) / s.sigma2));
    const float alpha = minf(s.opacity * TWO_PI * iu * iv, MAX_ALPHA);
    return composite_scalar(alpha, s.color, T, C);
}

// port of gaussian.h: gaussian_moment0 (GLSL has no erf either)
float gaussian_moment0(float x, float e) {
    const float z = abs(x) * 0.7071067811865476;
    const float t = 1.0 / (1.0 + 0.3275911 * z);
    const float poly =
        t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    const float erf_abs = 1.0 - poly * e;
    return SQRT_PI_2 * (x < 0.0 ? -erf_abs : erf_abs);
}

// port of gaussian.h: SideMoments, window_side_moments (one pixel: no lane mask; fast: its Fast, a constant)
struct SideMoments {
    float I0;
    float J1;
    float J2;
};

SideMoments window_side_moments(float c, float h, bool fast) {
    if (h > GB_SERIES_MAX_HALF_WIDTH) {
        const float a = c - h, b = c + h;
        const float ea = expf(-0.5 * a * a), eb = expf(-0.5 * b * b);
        const float I0 = gaussian_moment0(b, eb) - gaussian_moment0(a, ea);
        const float J1 = (ea - eb) - c * I0;
        return SideMoments(I0, J1, I0 - h * (ea + eb) - c * J1);
    }
    float he_prev = 1.0, he = c, p = h;  // He_{n-1}, He_n, h^n/n! at n = 1
    float s0 = 1.0, s1 = -(p * he) * (1.0 / 3.0), s2 = 1.0 / 3.0;
    // The exact precision takes every term, unlike gaussian.h (which stops at 6 or 10 for narrower windows; the sums
    // agree to ~1e-7): a loop with a data-dependent bound is not unrolled and would count towards llvmpipe's loop cap
    // (see gbviewer/render/glsl/limits.py). The fast one stops where gaussian.h's one-lane Fast does (its sums are
    // within its bound only, so they must match the other backends' term for term): a test in a loop of constant
    // bound once `fast` is folded.
    const int last = fast ? GB_FAST_SERIES_TERMS : GB_SERIES_TERMS;
    const int terms = !fast ? GB_SERIES_TERMS : h > 0.5 ? GB_FAST_SERIES_TERMS : h > 0.25 ? 6 : 4;
    for (int n = 2; n <= last; ++n) {
        if (n <= terms) {
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
    }
    const float two_h_e = fast ? 2.0 * h : 2.0 * h * expf(-0.5 * c * c);  // fast: blend_gaussian multiplies e(c)
    return SideMoments(two_h_e * s0, two_h_e * h * s1, two_h_e * h * h * s2);
}

// port of blend.h: TransmittanceWindow
struct TransmittanceWindow {
    float T;
    vec2 xy;
    vec2 wh;
};

// port of blend.h: blend_gaussian (the one-pixel wrapper's `fast`)
bool blend_gaussian(Splat2D s, inout TransmittanceWindow win, inout vec3 C, bool fast) {
    const vec2 d = win.xy - s.xy;
    const float reach = s.radius + 0.5 * (win.wh.x + win.wh.y);
    if (dot(d, d) > reach * reach) return false;
    const vec2 v2 = vec2(-s.v1.y, s.v1.x);
    const float u = dot(d, s.v1), v = dot(d, v2);
    const bool aligned = abs(s.v1.x) > abs(s.v1.y);
    const float lu = aligned ? win.wh.x : win.wh.y;
    const float lv = aligned ? win.wh.y : win.wh.x;
    const float gu = maxf(abs(u) - 0.5 * lu, 0.0) * s.inv_sigma1;
    const float gv = maxf(abs(v) - 0.5 * lv, 0.0) * s.inv_sigma2;
    if (-0.5 * (gu * gu + gv * gv) < s.log_min_alpha) return false;

    const float U1 = (u - 0.5 * lu) * s.inv_sigma1, U2 = (u + 0.5 * lu) * s.inv_sigma1;
    const float V1 = (v - 0.5 * lv) * s.inv_sigma2, V2 = (v + 0.5 * lv) * s.inv_sigma2;
    const float wu_s = U2 - U1, wv_s = V2 - V1;  // window sides in sigma units
    if (!(wu_s >= GB_MIN_UV_DIFF && wv_s >= GB_MIN_UV_DIFF && wu_s <= GB_MAX_UV_DIFF && wv_s <= GB_MAX_UV_DIFF)) {
        const float alpha = minf(s.opacity * gaussian_at(s, d), MAX_ALPHA);
        if (alpha < MIN_ALPHA_GB) return false;
        const float w = win.T * alpha;
        C[0] += s.color[0] * w;
        C[1] += s.color[1] * w;
        C[2] += s.color[2] * w;
        win.T -= w;
        return win.T < T_STOP;
    }
    const float cu = u * s.inv_sigma1, hu = 0.5 * lu * s.inv_sigma1;
    const float cv = v * s.inv_sigma2, hv = 0.5 * lv * s.inv_sigma2;
    const SideMoments mu_ = window_side_moments(cu, hu, fast);
    const SideMoments mv_ = window_side_moments(cv, hv, fast);
    const float i0u = s.sigma1 * mu_.I0, i0v = s.sigma2 * mv_.I0;
    const float inv_area = 1.0 / (lu * lv);
    // fast: the series sides' factors e(c) (window_side_moments) in one exp, blend.h's o, kept in the copy s.opacity:
    // naming o changes how Mesa compiles the exact variant's products, whose frames must stay bit for bit
    if (fast) {
        const float q =
            (hu <= GB_SERIES_MAX_HALF_WIDTH ? cu * cu : 0.0) + (hv <= GB_SERIES_MAX_HALF_WIDTH ? cv * cv : 0.0);
        s.opacity = s.opacity * expf(-0.5 * q);
    }
    const float alpha = minf(s.opacity * i0u * i0v * inv_area, MAX_ALPHA);
    if (alpha < MIN_ALPHA_GB) return false;
    const float weight = win.T * alpha;
    C[0] += s.color[0] * weight;
    C[1] += s.color[1] * weight;
    C[2] += s.color[2] * weight;

    const float k = win.T * inv_area * s.opacity;
    const float m0 = win.T - weight;
    const float m1u = -(k * (s.sigma1 * s.sigma1 * mu_.J1) * i0v), m1v = -(k * i0u * (s.sigma2 * s.sigma2 * mv_.J1));
    const float m2u = win.T * lu * lu * (1.0 / 12.0) - k * (s.sigma1 * s.sigma1 * s.sigma1 * mu_.J2) * i0v;
    const float m2v = win.T * lv * lv * (1.0 / 12.0) - k * i0u * (s.sigma2 * s.sigma2 * s.sigma2 * mv_.J2);
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

// port of blend.h: WsrSums. GLSL 4.30 core has no 64-bit integers: the sums are float, added in tile-list order
// (splat-index order), with the fixed-point terms' clamp (blend_oit.h: to_fixed) so that huge trained view
// weights weigh alike on every backend.
struct WsrSums {
    vec3 C;
    float S;
};

// port of blend_oit.h: blend_wsr (float sums, see WsrSums)
bool blend_wsr(Splat2D s, vec2 pix, inout WsrSums acc) {
    const float power = gaussian_power(s, s.xy - pix);
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects
    const float alpha = minf(s.opacity * expf(power), WSR_FIXED_MAX);
    if (alpha < MIN_ALPHA_3DGS) return false;
    acc.C[0] += minf(s.color[0] * alpha, WSR_FIXED_MAX);
    acc.C[1] += minf(s.color[1] * alpha, WSR_FIXED_MAX);
    acc.C[2] += minf(s.color[2] * alpha, WSR_FIXED_MAX);
    acc.S += alpha;
    return false;
}

// port of blend_oit.h: DuplexLanes (one pixel: blend.h's DuplexState)
struct DuplexState {
    float T;
    float T_cell;
    int cell;
    float S;
    vec3 C;
};

// port of blend_oit.h: blend_duplex
bool blend_duplex(Splat2D s, vec2 pix, float et_grade, inout DuplexState st) {
    const vec2 d = s.xy - pix;
    if (d.x * d.x + d.y * d.y > s.radius * s.radius) return false;
    const float power = gaussian_power(s, d);
    if (!(power <= 0.0 && power >= s.log_min_alpha)) return false;  // NaN rejects
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

// port of blend_oit.h: resolve_weighted (without its return value)
void resolve_weighted(vec3 C, float S, float wbg, float T_bg, out vec3 out_C, out float out_T) {
    float total = S + wbg * T_bg;
    if (total == 0.0) total = WSR_EMPTY_SUM;
    for (int c = 0; c < 3; ++c) out_C[c] = C[c] / total;
    out_T = wbg / total;
}

// ---- finishing a pixel ---------------------------------------------------------------------------------------------

// port of blend.h: PixelSums (wsr's are float here: blend.h's wsr_pixel_sums has nothing to convert)
struct PixelSums {
    vec3 C;
    float T;
    float S;
};

// port of blend.h: resolve_pixel, returning (rgb, alpha) and not the total
vec4 resolve_pixel(int mode, PixelSums p, float weight_background, vec3 bg) {
    vec3 C = p.C;
    float T = p.T;
    if (mode == WSR || mode == DUPLEX) {
        const float wbg = mode == DUPLEX && p.T < DUPLEX_T_STOP ? 0.0 : weight_background;
        resolve_weighted(p.C, p.S, wbg, p.T, C, T);
    }
    return vec4(C + T * bg, 1.0 - T);
}
