// `stochastic`: stochastic transparency for splats (StochasticSplats, Kheradmand et al., ICCV 2025,
// ubc-vision/stochasticsplats shader/splat_frag_ST.glsl; after Enderton et al., Stochastic Transparency, I3D 2010).
// Each splat fragment (splat, sample) is kept with probability alpha, alpha computed as `scalar` computes it (eq. 5,
// the 1/255 cut-off, the 0.99 clamp); a kept fragment is opaque (its colour, T = 0) and the depth test keeps the
// nearest kept fragment by the splat's centre depth (the published ST: every fragment of a splat's quad has the
// depth of its projected centre, shader/splat_geom.glsl offsetting the corners in x and y only). Lists are in
// centre-depth order, front to back (ties in list order, which a strict less-than depth test also keeps), so the
// nearest kept fragment is the first kept one: a lane stops there.
//
// Per sample: E[C] = sum_i c_i alpha_i prod_{j<i} (1 - alpha_j), E[T] = prod_i (1 - alpha_i): alpha blending in
// per-fragment depth order without early termination. Every sample of an N x N supersampled pixel (the sub-pixel
// (X, Y) of the supersampled grid) decides on its own, so `stochastic:N` converges to `scalar:N`.
//
// `stochastic_popfree` (StochasticSplats' ST-popfree, shader/splat_vert_ST_popfree.glsl) keeps the same fragments
// but depth-tests them at their depth along the pixel's ray on the splat's depth plane (popfree.h, one per splat
// beside the Splat2D): per pixel, the nearest kept fragment in that order, which is the order of the depths of
// maximum response along the ray to first order about the mean, and does not change when centre depths swap. The
// whole list is walked (no early stop).
// E[C] is then alpha blending in that per-pixel order.
//
// The decision u < alpha takes u from a hash of (seed, frame, X, Y, splat id): deterministic for a given seed and
// frame, stable for a splat under camera motion within a frame index (the splat id, not its list position, is
// hashed, as PlayCanvas and Spark hash it: sparkjsdev/spark src/shaders/splatFragment.glsl).
#pragma once

#include "blend.h"
#include "popfree.h"

namespace gbv {

// The 32-bit integer finaliser StochasticSplats hashes with (splat_frag_ST.glsl `hash`: xor-shift 16, multiply
// 0x7feb352d, xor-shift 15, multiply 0x846ca68b, xor-shift 16; a bijection of uint32).
GBV_HD uint32_t hash32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

// Unlike the published single packing of (x, y << 20, sample << 8, primitive + seed), which collides, every input is
// chained through its own hash: the frame's key once per frame, a sample's once per sample, a splat's once per splat.
GBV_HD uint32_t stochastic_frame_key(uint32_t seed, uint32_t frame) {
    return hash32(hash32(seed ^ 0x9e3779b9u) ^ frame);
}

// The key of sample (X, Y) of the supersampled grid (output pixel (X / N, Y / N), sample (X % N, Y % N)).
GBV_HD uint32_t stochastic_sample_key(uint32_t frame_key, uint32_t X, uint32_t Y) {
    return hash32(hash32(frame_key ^ X) ^ Y);
}

GBV_HD uint32_t stochastic_splat_key(int32_t id) { return hash32((uint32_t)id ^ 0x85ebca6bu); }

// The fragment's uniform in [0, 1): the top 24 bits of the hash, exact in float32. P(u < alpha) = ceil(alpha 2^24) /
// 2^24, within 2^-24 of alpha.
GBV_HD float stochastic_uniform(uint32_t sample_key, uint32_t splat_key) {
    return (float)(hash32(sample_key ^ splat_key) >> 8) * (1.0f / 16777216.0f);
}

// The keep decision of both stochastic modes for one splat on the lanes `live` (keys: each lane's sample key): the
// lanes whose centre alpha (centre_alpha, the 1/255 cut-off) exceeds the fragment's uniform. False when none keeps
// it. The uniforms are computed one lane at a time, so every lane type gives the same bits.
template <class L, class Tr = NoTrace>
GBV_HD bool stochastic_keep(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                            const uint32_t* keys, typename L::M& kept) {
    typename L::M pass;
    typename L::F alpha;
    if (!centre_alpha<L, Tr>(s, px, py, live, pass, alpha)) return false;
    GBV_TRACE(Tr, alpha(pass, alpha));
    GBV_TRACE(Tr, skip(L::and_(pass, alpha < L::set(MIN_ALPHA_3DGS)), SKIP_ALPHA));
    pass = L::and_not(pass, alpha < L::set(MIN_ALPHA_3DGS));
    const uint32_t bits = L::bits(pass);
    if (!bits) return false;
    const uint32_t splat_key = stochastic_splat_key(s.id);
    float u[L::N];
    GBV_UNROLL
    for (int k = 0; k < L::N; ++k) u[k] = (bits >> k) & 1u ? stochastic_uniform(keys[k], splat_key) : 1.0f;
    kept = L::and_(pass, L::load(u) < alpha);
    GBV_TRACE(Tr, skip(L::and_not(pass, kept), SKIP_DISCARD));
    return true;
}

// `stochastic`, one splat: the kept lanes take colour = the splat's, T = 0, and stop (the nearest kept fragment in
// a depth-ordered list). Returns those lanes.
template <class L, class Tr = NoTrace>
GBV_HD typename L::M blend_stochastic(const Splat2D& s, typename L::F px, typename L::F py, typename L::M live,
                                      const uint32_t* keys, AlphaState<L>& st) {
    typename L::M kept;
    if (!stochastic_keep<L, Tr>(s, px, py, live, keys, kept)) return L::none();
    GBV_TRACE(Tr, weight(kept, st.T));
    for (int c = 0; c < 3; ++c) st.C[c] = L::select(kept, L::set(s.color[c]), st.C[c]);
    st.T = L::select(kept, L::set(0.0f), st.T);
    return kept;
}

// Per-lane state of stochastic_popfree: the kept fragment's colour, T (1 until a fragment is kept, then 0) and its
// depth key (larger is nearer; -inf before any, so that a fragment at the lowest key, -FLT_MAX, can be kept).
template <class L>
struct PopfreeState {
    typename L::F T, key, C[3];
};

// One splat of stochastic_popfree: the keep decision, then the depth test against the lane's nearest kept fragment
// at the pixel's point of the splat's depth plane. Never stops a lane.
template <class L, class Tr = NoTrace>
GBV_HD void blend_stochastic_popfree(const Splat2D& s, const DepthPlane& plane, typename L::F px, typename L::F py,
                                     typename L::M live, const uint32_t* keys, PopfreeState<L>& st) {
    using F = typename L::F;
    using M = typename L::M;
    M kept;
    if (!stochastic_keep<L, Tr>(s, px, py, live, keys, kept)) return;
    // 1/z or -z on the plane; NaN (a splat without a plane: a needle, c = 0) is behind every plane
    F key = (L::set(plane.a) * px + L::set(plane.b) * py + L::set(plane.c)) / L::set(plane.d);
    key = L::select(key == key, key, L::set(-3.402823466e38f));
    const M nearer = L::and_(kept, key > st.key);
    GBV_TRACE(Tr, skip(L::and_not(kept, nearer), SKIP_DEPTH));
    GBV_TRACE(Tr, weight(nearer, L::set(1.0f)));
    for (int c = 0; c < 3; ++c) st.C[c] = L::select(nearer, L::set(s.color[c]), st.C[c]);
    st.T = L::select(nearer, L::set(0.0f), st.T);
    st.key = L::select(nearer, key, st.key);
}

// One pixel (CUDA's per-thread loop; the GLSL port has this name): the sample key `key`, T and C as blend_scalar's.
GBV_HD bool blend_stochastic(const Splat2D& s, Vec2 pix, uint32_t key, float& T, float C[3]) {
    AlphaState<Lanes1> st = {T, {C[0], C[1], C[2]}};
    const bool stop = blend_stochastic<Lanes1>(s, pix.x, pix.y, true, &key, st);
    T = st.T;
    for (int c = 0; c < 3; ++c) C[c] = st.C[c];
    return stop;
}

GBV_HD void blend_stochastic_popfree(const Splat2D& s, const DepthPlane& plane, Vec2 pix, uint32_t key, float& T,
                                     float& depth_key, float C[3]) {
    PopfreeState<Lanes1> st = {T, depth_key, {C[0], C[1], C[2]}};
    blend_stochastic_popfree<Lanes1>(s, plane, pix.x, pix.y, true, &key, st);
    T = st.T;
    depth_key = st.key;
    for (int c = 0; c < 3; ++c) C[c] = st.C[c];
}

}  // namespace gbv
