// Vector lanes for the blend and preprocess steps (gbv/lanes.h) on Google Highway: 8 floats with AVX2, 16 with
// AVX-512, 4 with NEON. Included by blend_isa.cpp and preprocess_isa.cpp, which are compiled once per instruction set with that
// set's -m flags, so Highway's static target (hwy::HWY_NAMESPACE, e.g. N_AVX2) is the one the files are built for and
// the type lives in that namespace.
#pragma once

#include <hwy/highway.h>

#include <type_traits>
#include <hwy/contrib/math/math-inl.h>

#include "gbv/common.h"

namespace gbv::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;

// Lanes of descriptor D_ (all of a vector: LanesHwy; 8 floats: PreprocessLanes).
template <class D_>
struct LanesOf {
    using D = D_;
    using DI = hn::RebindToSigned<D>;
    using F = hn::Vec<D>;
    using M = hn::Mask<D>;
    using I = hn::Vec<DI>;
    static constexpr int N = hn::MaxLanes(D());
    static HWY_INLINE F set(float v) { return hn::Set(D(), v); }
    static HWY_INLINE I seti(int32_t v) { return hn::Set(DI(), v); }
    static HWY_INLINE M none() { return hn::FirstN(D(), 0); }
    static HWY_INLINE bool any(M m) { return !hn::AllFalse(D(), m); }
    static HWY_INLINE M and_(M a, M b) { return hn::And(a, b); }
    static HWY_INLINE M or_(M a, M b) { return hn::Or(a, b); }
    static HWY_INLINE M and_not(M a, M b) { return hn::AndNot(b, a); }  // Highway's AndNot(x, y) is ~x & y
    static HWY_INLINE M eqi(I a, I b) { return hn::RebindMask(D(), a == b); }
    static HWY_INLINE F select(M m, F a, F b) { return hn::IfThenElse(m, a, b); }
    static HWY_INLINE I selecti(M m, I a, I b) { return hn::IfThenElse(hn::RebindMask(DI(), m), a, b); }
    static HWY_INLINE F neg(F x) { return hn::Neg(x); }
    static HWY_INLINE F abs(F x) { return hn::Abs(x); }
    static HWY_INLINE F min(F a, F b) { return hn::IfThenElse(a < b, a, b); }  // minf's NaN rule
    static HWY_INLINE F max(F a, F b) { return hn::IfThenElse(a > b, a, b); }
    static HWY_INLINE F sqrt(F x) { return hn::Sqrt(x); }
    // Highway's Exp: 1 ulp on [-FLT_MAX, 104], 0 below -104. Arguments above 88.7 overflow float anyway; the clamp
    // keeps them in Exp's range (the blend steps pass no NaN: they reject NaN exponents first).
    static HWY_INLINE F exp(F x) { return hn::Exp(D(), hn::Min(x, hn::Set(D(), 88.0f))); }
    static HWY_INLINE F load(const float* p) { return hn::LoadU(D(), p); }
    static HWY_INLINE M first_n(int k) { return hn::FirstN(D(), (size_t)(k < 0 ? 0 : k)); }
    static HWY_INLINE void store(F v, float* out) { hn::StoreU(v, D(), out); }
    static HWY_INLINE uint32_t bits(M m) {
        uint8_t b[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        hn::StoreMaskBits(D(), m, b);
        return (uint32_t)b[0] | (uint32_t)b[1] << 8;
    }
    static HWY_INLINE float reduce_min(F v) { return hn::GetLane(hn::MinOfLanes(D(), v)); }
    static HWY_INLINE float reduce_max(F v) { return hn::GetLane(hn::MaxOfLanes(D(), v)); }

    // For the preprocess (preprocess.h), bit-identical to Lanes1's libm functions on every lane. mul_rn: the product
    // passes through an empty asm statement, as gbv::mul_rn's does, so it is never fused into a multiply-add.
    static HWY_INLINE F mul_rn(F a, F b) {
        F p = a * b;
#if defined(__aarch64__)
        __asm__("" : "+w"(p.raw));  // a NEON register
#else
        __asm__("" : "+v"(p.raw));  // an SSE/AVX/AVX-512 register
#endif
        return p;
    }
    // fminf / fmaxf: a NaN argument yields the other one; equal arguments yield the first (glibc's rule; the sign of
    // a zero is the only difference it could make, and the preprocess never compares +0 with -0 where it matters)
    static HWY_INLINE F fmin(F a, F b) {
        return hn::IfThenElse(hn::IsNaN(a), b, hn::IfThenElse(hn::IsNaN(b), a, hn::IfThenElse(b < a, b, a)));
    }
    static HWY_INLINE F fmax(F a, F b) {
        return hn::IfThenElse(hn::IsNaN(a), b, hn::IfThenElse(hn::IsNaN(b), a, hn::IfThenElse(b > a, b, a)));
    }
    static HWY_INLINE F ceil(F x) { return hn::Ceil(x); }
    static HWY_INLINE M finite(F x) { return hn::IsFinite(x); }
    // frexpf by exact bit manipulation: x = m 2^e with |m| in [0.5, 1); zero, infinity and NaN give m = x, e = 0
    static HWY_INLINE F frexp(F x, I* e) {
        const DI di;
        const M sub = hn::And(hn::Abs(x) < set(1.17549435e-38f), x != set(0.0f));  // subnormal: scale by 2^24
        const F xs = hn::IfThenElse(sub, x * set(16777216.0f), x);
        const I bits = hn::BitCast(di, xs);
        const I field = hn::And(hn::ShiftRight<23>(bits), hn::Set(di, 0xff));
        const M special =
            hn::Or(hn::RebindMask(D(), field == hn::Zero(di)), hn::RebindMask(D(), field == hn::Set(di, 0xff)));
        const I mbits = hn::Or(hn::And(bits, hn::Set(di, (int32_t)0x807fffff)), hn::Set(di, 126 << 23));
        const I ex = field - hn::IfThenElse(hn::RebindMask(di, sub), hn::Set(di, 126 + 24), hn::Set(di, 126));
        *e = hn::IfThenElse(hn::RebindMask(di, special), hn::Zero(di), ex);
        return hn::IfThenElse(special, x, hn::BitCast(D(), mbits));
    }
    static HWY_INLINE I to_int(F x) { return hn::ConvertTo(DI(), x); }  // truncation
    static HWY_INLINE F to_float(I v) { return hn::ConvertTo(D(), v); }
    static HWY_INLINE M gti(I a, I b) { return hn::RebindMask(D(), a > b); }
    static HWY_INLINE void storei(I v, int32_t* out) { hn::StoreU(v, DI(), out); }

    // An N x N block of floats transposed by shuffles (moves, no arithmetic) where the preprocess would copy it float
    // by float: v[j]'s lane c becomes v[c]'s lane j. TRANSPOSES: x86's 8 x 8 (and the preprocess then also moves
    // rows in with load3 / load4).
    static constexpr bool TRANSPOSES = (HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3) && N == 8;  // 128-bit blocks
    static HWY_INLINE void transpose(F* v) {
        const D d;
        const hn::Repartition<uint64_t, D> d64;
        F t[8];
        for (int j = 0; j < 8; j += 2)  // per 128-bit block: (a0 b0 a1 b1), (a2 b2 a3 b3)
            t[j] = hn::InterleaveLower(d, v[j], v[j + 1]), t[j + 1] = hn::InterleaveUpper(d, v[j], v[j + 1]);
        for (int h = 0; h < 8; h += 4)  // (a0 b0 c0 d0), (a1 b1 c1 d1), (a2 ...), (a3 ...) per block
            for (int k = 0; k < 2; ++k) {
                const auto lo = hn::BitCast(d64, t[h + k]), hi = hn::BitCast(d64, t[h + 2 + k]);
                v[h + 2 * k] = hn::BitCast(d, hn::InterleaveLower(d64, lo, hi));
                v[h + 2 * k + 1] = hn::BitCast(d, hn::InterleaveUpper(d64, lo, hi));
            }
        for (int c = 0; c < 4; ++c)  // rows 0-3's block then rows 4-7's: the low blocks are columns 0-3
            t[c] = hn::ConcatLowerLower(d, v[4 + c], v[c]), t[4 + c] = hn::ConcatUpperUpper(d, v[4 + c], v[c]);
        for (int c = 0; c < 8; ++c) v[c] = t[c];
    }
    // v[c] = lane j: p[3 j + c] (load3) or p[4 j + c] (load4), j < N: N rows of 3 or 4 floats deinterleaved.
    static HWY_INLINE void load3(const float* p, F* v) { hn::LoadInterleaved3(D(), p, v[0], v[1], v[2]); }
    static HWY_INLINE void load4(const float* p, F* v) { hn::LoadInterleaved4(D(), p, v[0], v[1], v[2], v[3]); }
    // cols[c] = lane j: rows[j][c0 + c] (c, j < N).
    static HWY_INLINE void transpose(const float* const* rows, int c0, F* cols) {
        for (int j = 0; j < N; ++j) cols[j] = hn::LoadU(D(), rows[j] + c0);
        transpose(cols);
    }
};

using LanesHwy = LanesOf<hn::ScalableTag<float>>;

// The preprocess's lanes: 8 floats on x86 (AVX-512 too: its stage and finish move records of 8 floats in and out by
// the 8 x 8 transposes, which 16 lanes moved float by float were slower than; bench/RESULTS.md), all of a vector
// elsewhere.
#if HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3
using PreprocessLanes = LanesOf<hn::CappedTag<float, 8>>;
#else
using PreprocessLanes = LanesHwy;
#endif

}  // namespace gbv::HWY_NAMESPACE

namespace gbv::HWY_NAMESPACE {

// Two vectors as one lane type of 2N lanes: a whole 16-pixel tile row per splat walk with AVX2 (half a row with NEON),
// which halves the per-splat work outside the lanes and gives the core two independent dependency chains.
template <class V>
struct Pair {
    V a, b;
};
template <class V>
HWY_INLINE Pair<V> operator+(Pair<V> x, Pair<V> y) {
    return {x.a + y.a, x.b + y.b};
}
template <class V>
HWY_INLINE Pair<V> operator-(Pair<V> x, Pair<V> y) {
    return {x.a - y.a, x.b - y.b};
}
template <class V>
HWY_INLINE Pair<V> operator*(Pair<V> x, Pair<V> y) {
    return {x.a * y.a, x.b * y.b};
}
template <class V>
HWY_INLINE Pair<V> operator/(Pair<V> x, Pair<V> y) {
    return {x.a / y.a, x.b / y.b};
}
#define GBV_PAIR_CMP(op)                                                      \
    template <class V>                                                        \
    HWY_INLINE Pair<decltype(V() op V())> operator op(Pair<V> x, Pair<V> y) { \
        return {x.a op y.a, x.b op y.b};                                      \
    }
GBV_PAIR_CMP(<)
GBV_PAIR_CMP(>)
GBV_PAIR_CMP(<=)
GBV_PAIR_CMP(>=)
GBV_PAIR_CMP(==)
#undef GBV_PAIR_CMP

template <class L>
struct LanesX2 {
    using Half = L;  // the lane type of each half (blend_tile.h steps one half alone when only it can take a splat)
    using F = Pair<typename L::F>;
    using M = Pair<typename L::M>;
    using I = Pair<typename L::I>;
    static constexpr int N = 2 * L::N;
    static HWY_INLINE F set(float v) { return {L::set(v), L::set(v)}; }
    static HWY_INLINE I seti(int32_t v) { return {L::seti(v), L::seti(v)}; }
    static HWY_INLINE M none() { return {L::none(), L::none()}; }
    static HWY_INLINE bool any(M m) { return L::any(L::or_(m.a, m.b)); }
    static HWY_INLINE M and_(M x, M y) { return {L::and_(x.a, y.a), L::and_(x.b, y.b)}; }
    static HWY_INLINE M or_(M x, M y) { return {L::or_(x.a, y.a), L::or_(x.b, y.b)}; }
    static HWY_INLINE M and_not(M x, M y) { return {L::and_not(x.a, y.a), L::and_not(x.b, y.b)}; }
    static HWY_INLINE M eqi(I x, I y) { return {L::eqi(x.a, y.a), L::eqi(x.b, y.b)}; }
    static HWY_INLINE F select(M m, F x, F y) { return {L::select(m.a, x.a, y.a), L::select(m.b, x.b, y.b)}; }
    static HWY_INLINE I selecti(M m, I x, I y) { return {L::selecti(m.a, x.a, y.a), L::selecti(m.b, x.b, y.b)}; }
    static HWY_INLINE F neg(F x) { return {L::neg(x.a), L::neg(x.b)}; }
    static HWY_INLINE F abs(F x) { return {L::abs(x.a), L::abs(x.b)}; }
    static HWY_INLINE F min(F x, F y) { return {L::min(x.a, y.a), L::min(x.b, y.b)}; }
    static HWY_INLINE F max(F x, F y) { return {L::max(x.a, y.a), L::max(x.b, y.b)}; }
    static HWY_INLINE F sqrt(F x) { return {L::sqrt(x.a), L::sqrt(x.b)}; }
    static HWY_INLINE F exp(F x) { return {L::exp(x.a), L::exp(x.b)}; }
    static HWY_INLINE F load(const float* p) { return {L::load(p), L::load(p + L::N)}; }
    static HWY_INLINE M first_n(int k) { return {L::first_n(k), L::first_n(k - L::N)}; }
    static HWY_INLINE void store(F v, float* out) {
        L::store(v.a, out);
        L::store(v.b, out + L::N);
    }
    static HWY_INLINE uint32_t bits(M m) { return L::bits(m.a) | L::bits(m.b) << L::N; }
    static HWY_INLINE float reduce_min(F v) { return L::reduce_min(L::min(v.a, v.b)); }
    static HWY_INLINE float reduce_max(F v) { return L::reduce_max(L::max(v.a, v.b)); }
};

// The lane type the blend uses: one tile row (16 pixels) per group, half a row (8) with NEON.
using BlendLanes = std::conditional_t<(LanesHwy::N >= 16), LanesHwy, LanesX2<LanesHwy>>;

}  // namespace gbv::HWY_NAMESPACE
