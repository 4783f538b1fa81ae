// The splat's Gaussian and its integrals, shared by the blend steps (blend.h, blend_oit.h): its exponent at an
// offset, the normal CDF approximation of `analytic`, and the moments of exp(-t^2/2) over a window side that
// `gaussian_blending` updates its window with. Templates over a lane type L (lanes.h), as blend.h's steps.
#pragma once

#include "common.h"
#include "lanes.h"

namespace gbv {

// Exponent of the splat's Gaussian at offset (dx, dy) from its centre (eq. 5; either sign of the offset).
template <class L>
GBV_HD typename L::F gaussian_power(const Splat2D& s, typename L::F dx, typename L::F dy) {
    return L::set(-0.5f) * (L::set(s.conic[0]) * dx * dx + L::set(s.conic[2]) * dy * dy) - L::set(s.conic[1]) * dx * dy;
}

// Analytic-Splatting's logistic approximation of the standard normal CDF (docs/modes.md#analytic):
// sigmoid(1.6x + 0.07x^3), written with exp (the published 0.5 tanh(z/2) + 0.5 is the same function).
template <class L>
GBV_HD typename L::F approx_cdf(typename L::F x) {
    return L::set(1.0f) / (L::set(1.0f) + L::exp(L::neg(L::set(1.6f) * x + L::set(0.07f) * x * x * x)));
}

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
// splat's tails. Wider windows use the closed form about the centre: J1 = e(a) - e(b) - c I0,
// J2 = I0 - h (e(a) + e(b)) - c J1.
//
// Fast (Gaussian Blending's `fast` precision): the series from 4 to GB_FAST_SERIES_TERMS terms by h (absolute error of
// the window mean and of the normalised J1, J2 < 7e-5 against float64, see tests/render/test_gb_fast.py), and the
// series lanes' moments are returned without their factor e(c): the caller multiplies both sides' factors into one
// exp (blend_gaussian), which every product of the update carries once.
template <class L>
struct SideMoments {
    typename L::F I0, J1, J2;
};

template <class L, bool Fast = false>
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
        const int wide = L::any(L::and_(series, hs > L::set(0.5f)))    ? 2
                         : L::any(L::and_(series, hs > L::set(0.25f))) ? 1
                                                                       : 0;
        const int terms = Fast ? (wide == 2   ? GB_FAST_SERIES_TERMS
                                  : wide == 1 ? 6
                                              : 4)
                               : (wide == 2   ? GB_SERIES_TERMS
                                  : wide == 1 ? 10
                                              : 6);
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
        F two_h_e = L::set(2.0f) * hs;
        if constexpr (!Fast) two_h_e = two_h_e * L::exp(m * cc * cc);
        out.I0 = L::select(series, two_h_e * s0, out.I0);
        out.J1 = L::select(series, two_h_e * hs * s1, out.J1);
        out.J2 = L::select(series, two_h_e * hs * hs * s2, out.J2);
    }
    return out;
}

}  // namespace gbv
