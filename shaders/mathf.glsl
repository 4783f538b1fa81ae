// The <cmath> functions the native kernels use where GLSL's built-ins are allowed to be approximate: expf, logf.
// Same names as the C functions, so the ported kernels read like native/include/gbv/*.h.
//
// GLSL leaves the precision of exp() and log() to the driver (llvmpipe's exp is off by up to 2e-6 relative,
// ~30 ulp), which would move alphas and transmittances across the 1/255 and 1e-4 cuts more often than glibc's
// expf/logf do. With GBV_PRECISE_MATH (the driver's default) both are range-reduced polynomials of ~1-2 ulp;
// with GBV_PRECISE_MATH 0 they are the built-ins (faster on GPUs with hardware exp2/log2).
#ifndef GBV_PRECISE_MATH
#define GBV_PRECISE_MATH 1
#endif

// e^x = 2^k e^r with x = k ln2 + r, |r| <= ln2/2; e^r by its Taylor series to r^7 (truncation 5.6e-9 relative).
// Below -87.3 the result would be subnormal (glibc returns ~1e-38 there; every caller compares it with
// thresholds >= 1e-4 or adds it to O(1) terms) and 0 is returned.
float expf(float x) {
#if GBV_PRECISE_MATH
    if (x < -87.3) return 0.0;
    x = min(x, 88.7);
    const float k = round(x * 1.44269504);  // 1 / ln 2
    const float r = (x - k * 0.693145751953125) - k * 1.428606765330187e-06;  // ln 2 = hi + lo, k * hi exact
    float p = 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    return ldexp(p, int(k));
#else
    return exp(x);
#endif
}

// ln x = e ln2 + ln m with x = m 2^e, m in [sqrt(1/2), sqrt(2)); ln m = 2 atanh(s), s = (m - 1) / (m + 1),
// |s| <= 0.172, by its series to s^11 (truncation 7e-11). x <= 0 gives -inf (x = 0) or NaN, as logf.
float logf(float x) {
#if GBV_PRECISE_MATH
    if (!(x > 0.0) || isinf(x)) return log(x);
    int e;
    float m = frexp(x, e);  // m in [0.5, 1)
    if (m < 0.70710678) {
        m *= 2.0;
        e -= 1;
    }
    const float s = (m - 1.0) / (m + 1.0), s2 = s * s;
    float p = 1.0 / 11.0;
    p = p * s2 + 1.0 / 9.0;
    p = p * s2 + 1.0 / 7.0;
    p = p * s2 + 1.0 / 5.0;
    p = p * s2 + 1.0 / 3.0;
    p = p * s2 + 1.0;
    const float ef = float(e);
    return (2.0 * s * p + ef * 1.428606765330187e-06) + ef * 0.693145751953125;
#else
    return log(x);
#endif
}
