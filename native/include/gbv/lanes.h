// Lane types for the blend steps of blend.h and the preprocess of preprocess.h. Each step is written once over a lane type L: L::F holds one float
// per pixel lane, L::M one flag per lane, L::I one int32 per lane. `Lanes1` is one pixel (the scalar CPU path and
// CUDA, one thread per pixel); the CPU's vector types (native/cpu/lanes_hwy.h, Google Highway) hold 8 or 16
// pixels. Arithmetic uses the types' operators; everything else goes through these static functions, so the
// same source compiles to plain branches for one pixel and to masked vector code for many.
#pragma once

#include "common.h"

namespace gbv {

struct Lanes1 {
    static constexpr int N = 1;
    static constexpr bool TRANSPOSES = false;  // no shuffled moves (the CPU's LanesHwy has them on AVX2)
    using F = float;
    using M = bool;
    using I = int32_t;
    static GBV_HDI F set(float v) { return v; }
    static GBV_HDI I seti(int32_t v) { return v; }
    static GBV_HDI M none() { return false; }
    static GBV_HDI bool any(M m) { return m; }
    static GBV_HDI M and_(M a, M b) { return a && b; }
    static GBV_HDI M or_(M a, M b) { return a || b; }
    static GBV_HDI M and_not(M a, M b) { return a && !b; }  // a and not b
    static GBV_HDI M eqi(I a, I b) { return a == b; }
    static GBV_HDI F select(M m, F a, F b) { return m ? a : b; }
    static GBV_HDI I selecti(M m, I a, I b) { return m ? a : b; }
    static GBV_HDI F neg(F x) { return -x; }
    static GBV_HDI F abs(F x) { return fabsf(x); }
    static GBV_HDI F min(F a, F b) { return a < b ? a : b; }  // minf: a NaN first argument yields b
    static GBV_HDI F max(F a, F b) { return a > b ? a : b; }
    static GBV_HDI F sqrt(F x) { return sqrtf(x); }
    static GBV_HDI F exp(F x) { return expf(x); }
    static GBV_HDI F load(const float* p) { return p[0]; }
    static GBV_HDI M first_n(int k) { return k > 0; }  // lanes 0..k-1
    static GBV_HDI void store(F v, float* out) { out[0] = v; }
    static GBV_HDI uint32_t bits(M m) { return m ? 1u : 0u; }  // bit i: lane i
    static GBV_HDI float reduce_min(F v) { return v; }
    static GBV_HDI float reduce_max(F v) { return v; }
    // for the preprocess (preprocess.h): libm's rules, bit for bit on every lane type
    static GBV_HDI F mul_rn(F a, F b) { return gbv::mul_rn(a, b); }
    static GBV_HDI F fmin(F a, F b) { return fminf(a, b); }  // a NaN argument yields the other one
    static GBV_HDI F fmax(F a, F b) { return fmaxf(a, b); }
    static GBV_HDI F ceil(F x) { return ceilf(x); }
    static GBV_HDI M finite(F x) { return finitef(x); }
    static GBV_HDI F frexp(F x, I* e) { return frexpf(x, e); }
    static GBV_HDI I to_int(F x) { return (int32_t)x; }  // truncation
    static GBV_HDI F to_float(I v) { return (float)v; }
    static GBV_HDI M gti(I a, I b) { return a > b; }
};

}  // namespace gbv
