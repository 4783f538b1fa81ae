// The CPU's preprocess of a range of splats in two passes, written once over a lane type L (gbv/lanes.h; Lanes1: the
// scalar path, blend_scalar.cpp; Highway's vectors: preprocess_isa.cpp, once per instruction set): stage_range runs
// the per-camera stage (gbv/preprocess_stage.h) and stores it, finish_range runs a mode's finish
// (gbv/preprocess.h) on the stored stage. Each moves L::N splats into lanes and each lane's result out again:
// bit-identical to preprocess_splat one splat at a time (storing floats and loading them is exact).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstddef>
#include <cstring>

#include "gbv/popfree.h"
#include "gbv/preprocess.h"

namespace gbv {

// StageJob::depth of a splat that is not valid (a valid one is in front of the near plane: a positive depth, whose
// float bits are below 2^31).
constexpr uint32_t NO_DEPTH = 0xFFFFFFFFu;

// A splat's depth key, the depth order's: depth bits in the high 32 bits (depth > near > 0: the bits order as the
// floats), id low.
inline uint64_t depth_key(uint32_t depth_bits, uint32_t id) { return ((uint64_t)depth_bits << 32) | id; }

// The stage of one camera: the scene (activated parameters, gbviewer.Scene's layout), the camera and SH degree, and
// per splat its StageSplat, flag (in front of the near plane and possibly on screen in some mode) and depth bits
// (the depth order's keys, 4 bytes a splat: its sort reads them instead of the 40-byte records). Plain data, shared
// by the translation units of every instruction set.
struct StageJob {
    const float *means, *scales, *quats, *opacities, *sh, *filter_3d;  // filter_3d may be null
    int k;  // SH coefficients per channel
    int sh_deg;
    CameraParams cam;
    float reach;  // StageKey::reach (stage_on_screen)
    int rules;  // StageKey::rules (stage_rules)
    int grid_x, grid_y;
    StageSplat* stage;
    uint8_t* valid;
    uint32_t* depth;  // the float bits of a valid splat's depth, else NO_DEPTH
    // A level-of-detail frame's cut, drawn in place: stage splat i is row rows[i] of the scene's arrays, or, from
    // n_scene on, interior node rows[i] - n_scene of the hierarchy's (the same layouts), its opacity times
    // weights[i] (as gathering the cut into a scene of its own multiplies it). rows null: splat i is row i.
    const int32_t* rows = nullptr;
    const float* weights = nullptr;
    int64_t n_scene = 0;
    const float *node_means = nullptr, *node_scales = nullptr, *node_quats = nullptr, *node_opacities = nullptr,
                *node_sh = nullptr, *node_filter_3d = nullptr;

    int64_t row(int64_t i) const { return rows ? rows[i] : i; }
    // Whether rows r[0..n) are n consecutive rows of one array (the scene's or the hierarchy's), in order (a cut's
    // leaves come in the tree's order: rows 7, 9, 8, 10 are not a run).
    bool run(const int64_t* r, int n) const {
        for (int j = 1; j < n; ++j)
            if (r[j] != r[0] + j) return false;
        return (r[0] < n_scene) == (r[n - 1] < n_scene);
    }
    // Row r (width floats) of an input: the scene's array, or past n_scene the hierarchy's.
    const float* at(const float* scene, const float* nodes, int width, int64_t r) const {
        return r < n_scene || !nodes ? scene + (size_t)width * r : nodes + (size_t)width * (r - n_scene);
    }
};

// One mode's finish of a stored stage: the view weights (wsr, duplex) and cells, and the per-splat outputs.
struct FinishJob {
    const float* means;
    const float *scales, *quats, *filter_3d;  // stochastic_popfree's depth planes (filter_3d may be null)
    const float* weight_sh;  // (n, weight_k) or null
    int weight_k;
    const int32_t* cell_of;  // duplex: each splat's cell; null: -1
    int sh_deg;
    CameraParams cam;
    Mode mode;
    OitParams oit;
    int grid_x, grid_y;
    const StageSplat* stage;
    const uint8_t* stage_valid;
    Splat2D* splats;
    TileRect* rects;  // empty (0, 0, 0, 0) where not valid
    uint8_t* valid;
    DepthPlane* planes;  // stochastic_popfree: each valid splat's depth plane; null in the other modes
};

// Splats [begin, end) of a job.
using StageFn = void (*)(const StageJob& job, int64_t begin, int64_t end);
using FinishFn = void (*)(const FinishJob& job, int64_t begin, int64_t end);

// Splats i0 .. i0 + count - 1 of the (n, width) array src into lane buffers buf[0..width) (spare lanes repeat the
// last splat).
template <int N>
inline void gather_lanes(const float* src, int width, const int64_t* ids, int count, float (*buf)[N]) {
    if (count <= 0) return;
    for (int j = 0; j < N; ++j) {
        const float* s = src + (size_t)width * ids[j < count ? j : count - 1];
        for (int c = 0; c < width; ++c) buf[c][j] = s[c];
    }
}

// The stage's inputs of rows[0..count) (StageJob::row) into lane buffers buf[0..width) (spare lanes repeat the last).
template <int N>
inline void gather_rows(const StageJob& job, const float* scene, const float* nodes, int width, const int64_t* rows,
                        int count, float (*buf)[N]) {
    for (int j = 0; j < N; ++j) {
        const float* s = job.at(scene, nodes, width, rows[j < count ? j : count - 1]);
        for (int c = 0; c < width; ++c) buf[c][j] = s[c];
    }
}

// SH colours of the stage splats ids[0..count) into their stage.
template <class L>
void stage_colors(const StageJob& job, const int64_t* ids, int count) {
    constexpr int N = L::N;
    const int nsh = (job.sh_deg + 1) * (job.sh_deg + 1) * 3;  // coefficients sh_to_rgb reads
    alignas(64) float mb[3][N], shb[48][N];
    alignas(64) float o[3][N];
    typename L::F sh[48];
    int64_t rows[N];
    for (int g = 0; g < count; g += N) {
        const int c = count - g < N ? count - g : N;
        // ask for the SH rows ahead: a level-of-detail cut's scattered rows two groups ahead, the scene's four (the
        // hardware prefetcher alone lets a large scene's stage wait on them)
        const int ahead = job.rows ? 2 : 4;
        for (int a = g + ahead * N; a < std::min(g + (ahead + 1) * N, count); ++a) {
            const char* p = (const char*)job.at(job.sh, job.node_sh, job.k * 3, job.row(ids[a]));
            for (int b = 0; b < nsh * (int)sizeof(float); b += 64) __builtin_prefetch(p + b);
            __builtin_prefetch(p + nsh * sizeof(float) - 1);
        }
        for (int j = 0; j < N; ++j) rows[j] = job.row(ids[g + (j < c ? j : c - 1)]);  // spare lanes repeat the last
        SplatInLanes<L> in;
        bool moved = false;
        if constexpr (L::TRANSPOSES)
            if (c == N && job.run(rows, N)) {  // N consecutive rows (no spare lane)
                L::load3(job.at(job.means, job.node_means, 3, rows[0]), in.mean);
                moved = true;
            }
        if (!moved) {
            gather_rows<N>(job, job.means, job.node_means, 3, rows, c, mb);
            for (int q = 0; q < 3; ++q) in.mean[q] = L::load(mb[q]);
        }
        const float* srow[N];  // the first nsh of k * 3 coefficients of each
        for (int j = 0; j < N; ++j) srow[j] = job.at(job.sh, job.node_sh, job.k * 3, rows[j]);
        int q0 = 0;
        if constexpr (L::TRANSPOSES)
            for (; q0 + N <= nsh; q0 += N) L::transpose(srow, q0, sh + q0);
        for (int j = 0; j < N; ++j)
            for (int q = q0; q < nsh; ++q) shb[q][j] = srow[j][q];
        for (int q = q0; q < nsh; ++q) sh[q] = L::load(shb[q]);
        in.sh = sh;
        typename L::F color[3];
        stage_color<L>(in, job.sh_deg, job.rules, job.cam, color);
        for (int q = 0; q < 3; ++q) L::store(color[q], o[q]);
        for (int j = 0; j < c; ++j)
            for (int q = 0; q < 3; ++q) job.stage[ids[g + j]].color[q] = o[q][j];
    }
}

template <class L>
void stage_range(const StageJob& job, int64_t begin, int64_t end) {
    constexpr int N = L::N;
    constexpr int BLOCK = 256;  // splats whose colours are evaluated together, on-screen lanes packed
    alignas(64) float buf[12][N];  // means, scales, quats, opacity, filter_3d
    alignas(64) float o[8][N];
    int64_t rows[N], on[BLOCK];
    for (int64_t b0 = begin; b0 < end; b0 += BLOCK) {
        const int64_t b1 = end - b0 < BLOCK ? end : b0 + BLOCK;
        int count_on = 0;
        for (int64_t i0 = b0; i0 < b1; i0 += N) {
            const int count = b1 - i0 < N ? (int)(b1 - i0) : N;
            if (job.rows)  // a cut's rows are scattered: ask for their geometry two groups ahead
                for (int64_t a = i0 + 2 * N; a < std::min<int64_t>(i0 + 3 * N, end); ++a) {
                    const int64_t r = job.rows[a];
                    __builtin_prefetch(job.at(job.means, job.node_means, 3, r));
                    __builtin_prefetch(job.at(job.scales, job.node_scales, 3, r));
                    __builtin_prefetch(job.at(job.quats, job.node_quats, 4, r));
                    __builtin_prefetch(job.at(job.opacities, job.node_opacities, 1, r));
                    if (job.filter_3d) __builtin_prefetch(job.at(job.filter_3d, job.node_filter_3d, 1, r));
                }
            SplatInLanes<L> in;
            for (int j = 0; j < count; ++j) rows[j] = job.row(i0 + j);
            bool moved = false;
            if constexpr (L::TRANSPOSES)
                if (count == N && job.run(rows, N)) {  // N consecutive rows: deinterleaved by shuffles
                    const int64_t r = rows[0];
                    L::load3(job.at(job.means, job.node_means, 3, r), in.mean);
                    L::load3(job.at(job.scales, job.node_scales, 3, r), in.scale);
                    L::load4(job.at(job.quats, job.node_quats, 4, r), in.quat);
                    in.opacity = L::load(job.at(job.opacities, job.node_opacities, 1, r));
                    if (job.weights) in.opacity = in.opacity * L::load(job.weights + i0);
                    in.filter_3d =
                        job.filter_3d ? L::load(job.at(job.filter_3d, job.node_filter_3d, 1, r)) : L::set(0.0f);
                    moved = true;
                }
            if (!moved) {
                gather_rows<N>(job, job.means, job.node_means, 3, rows, count, buf);
                gather_rows<N>(job, job.scales, job.node_scales, 3, rows, count, buf + 3);
                gather_rows<N>(job, job.quats, job.node_quats, 4, rows, count, buf + 6);
                gather_rows<N>(job, job.opacities, job.node_opacities, 1, rows, count, buf + 10);
                if (job.weights)
                    for (int j = 0; j < N; ++j) buf[10][j] *= job.weights[i0 + (j < count ? j : count - 1)];
                for (int j = 0; j < N; ++j)
                    buf[11][j] = job.filter_3d
                                     ? *job.at(job.filter_3d, job.node_filter_3d, 1, rows[j < count ? j : count - 1])
                                     : 0.0f;
                for (int c = 0; c < 3; ++c) in.mean[c] = L::load(buf[c]);
                for (int c = 0; c < 3; ++c) in.scale[c] = L::load(buf[3 + c]);
                for (int c = 0; c < 4; ++c) in.quat[c] = L::load(buf[6 + c]);
                in.opacity = L::load(buf[10]);
                in.filter_3d = L::load(buf[11]);
            }
            StageLanes<L> st{};  // preprocess_stage leaves it unset when no lane is in front
            uint32_t ok = L::bits(preprocess_stage<L>(in, job.cam, job.rules, &st));
            if (ok) ok &= L::bits(stage_on_screen<L>(st, job.grid_x, job.grid_y, job.reach));
            for (int j = 0; j < count; ++j) job.valid[i0 + j] = (ok >> j) & 1u;
            if (!ok) {
                std::fill(job.depth + i0, job.depth + i0 + count, NO_DEPTH);
                continue;
            }
            const typename L::F fields[7] = {st.xy[0], st.xy[1], st.depth, st.opacity, st.cov[0], st.cov[1], st.cov[2]};
            for (int f = 0; f < 7; ++f) L::store(fields[f], o[f]);
            // with transposes: each lane's record as one row of 8 (the 8th, colour 0, is written by stage_colors
            // below, as every valid lane's colour)
            typename L::F rec[N];
            if constexpr (L::TRANSPOSES) {
                static_assert(offsetof(StageSplat, cov) == 16 && offsetof(StageSplat, color) == 28);
                std::copy(fields, fields + 7, rec);
                rec[7] = st.cov[2];
                L::transpose(rec);
            }
            for (int j = 0; j < count; ++j) {
                job.depth[i0 + j] = NO_DEPTH;
                if (!((ok >> j) & 1u)) continue;
                std::memcpy(&job.depth[i0 + j], &o[2][j], 4);
                StageSplat& s = job.stage[i0 + j];
                if constexpr (L::TRANSPOSES) {
                    L::store(rec[j], s.xy);
                } else {
                    s.xy[0] = o[0][j];
                    s.xy[1] = o[1][j];
                    s.depth = o[2][j];
                    s.opacity = o[3][j];
                    for (int c = 0; c < 3; ++c) s.cov[c] = o[4 + c][j];
                }
                on[count_on++] = i0 + j;
            }
        }
        stage_colors<L>(job, on, count_on);
    }
}

template <class L>
void finish_range(const FinishJob& job, int64_t begin, int64_t end) {
    using F = typename L::F;
    constexpr int N = L::N;
    const int weight_deg = sh_degree_for_coeffs(job.weight_k);
    const bool weights = (job.mode == WSR || job.mode == DUPLEX) && job.weight_sh;
    const int wdeg = job.sh_deg < weight_deg ? job.sh_deg : weight_deg;
    const int nw = weights ? (wdeg + 1) * (wdeg + 1) : 0;  // coefficients sh_to_weight reads
    alignas(64) float sb[8][N], mb[3][N], wb[16][N];
    alignas(64) float o[14][N];
    alignas(64) int32_t rb[4][N];
    F w[16];
    int64_t ids[N];
    // written whole for a group with a valid lane, not read for the others: zeroed once here, not per group (a
    // group's zeroing is a visible part of the finish's cost)
    Splat2DLanes<L> out{};
    TileRectLanes<L> rect{};
    typename L::F cols[N], color[N];  // with transposes: the stage's records as lanes
    for (int64_t i0 = begin; i0 < end; i0 += N) {
        const int count = end - i0 < N ? (int)(end - i0) : N;
        bool any = false;
        for (int j = 0; j < count; ++j) any |= job.stage_valid[i0 + j] != 0;
        if (!any) {  // culled in the stage: culled in every mode
            for (int j = 0; j < count; ++j) job.valid[i0 + j] = 0, job.rects[i0 + j] = TileRect{0, 0, 0, 0};
            continue;
        }
        StageLanes<L> st;
        if constexpr (L::TRANSPOSES) {  // the records' first 8 floats: xy, depth, opacity, cov, (colour)
            static_assert(offsetof(StageSplat, cov) == 16 && sizeof(StageSplat) >= 8 * sizeof(float));
            const float* rec[N];
            for (int j = 0; j < N; ++j) {
                const int64_t i = i0 + (j < count ? j : count - 1);  // spare lanes repeat the last splat
                ids[j] = i;
                rec[j] = job.stage[i].xy;
                sb[7][j] = job.stage_valid[i] ? 1.0f : 0.0f;
            }
            L::transpose(rec, 0, cols);
            st.xy[0] = cols[0], st.xy[1] = cols[1], st.depth = cols[2], st.opacity = cols[3];
            for (int c = 0; c < 3; ++c) st.cov[c] = cols[4 + c];
            L::transpose(rec, 2, color);  // colour 1, 2 in lanes 6, 7
        } else {
            for (int j = 0; j < N; ++j) {
                const int64_t i = i0 + (j < count ? j : count - 1);  // spare lanes repeat the last splat
                ids[j] = i;
                const StageSplat& s = job.stage[i];
                const float f[8] = {s.xy[0],  s.xy[1],  s.depth,  s.opacity,
                                    s.cov[0], s.cov[1], s.cov[2], job.stage_valid[i] ? 1.0f : 0.0f};
                for (int c = 0; c < 8; ++c) sb[c][j] = f[c];
            }
            st.xy[0] = L::load(sb[0]);
            st.xy[1] = L::load(sb[1]);
            st.depth = L::load(sb[2]);
            st.opacity = L::load(sb[3]);
            for (int c = 0; c < 3; ++c) st.cov[c] = L::load(sb[4 + c]);
        }
        SplatInLanes<L> in{};  // the finish reads mean and weight_sh only where weights are given
        in.weight_deg = weight_deg;
        if (weights) {
            gather_lanes<N>(job.means, 3, ids, count, mb);
            gather_lanes<N>(job.weight_sh, job.weight_k, ids, count, wb);  // the first nw are read
            for (int c = 0; c < 3; ++c) in.mean[c] = L::load(mb[c]);
            for (int q = 0; q < nw; ++q) w[q] = L::load(wb[q]);
            in.weight_sh = w;
        }
        const uint32_t ok = L::bits(preprocess_finish<L>(in, st, L::load(sb[7]) > L::set(0.0f), job.sh_deg, job.cam,
                                                         job.mode, job.oit, job.grid_x, job.grid_y, &out, &rect));
        for (int j = 0; j < count; ++j) {
            job.valid[i0 + j] = (ok >> j) & 1u;
            if (!((ok >> j) & 1u)) job.rects[i0 + j] = TileRect{0, 0, 0, 0};
        }
        if (!ok) continue;
        const F fields[14] = {out.xy[0],    out.xy[1],      out.depth,      out.opacity, out.conic[0],
                              out.conic[1], out.conic[2],   out.v1[0],      out.v1[1],   out.sigma1,
                              out.sigma2,   out.inv_sigma1, out.inv_sigma2, out.radius};
        for (int f = 0; f < 14; ++f) L::store(fields[f], o[f]);
        if constexpr (N == 1) {
            rb[0][0] = rect.x0, rb[1][0] = rect.y0, rb[2][0] = rect.x1, rb[3][0] = rect.y1;
        } else {
            L::storei(rect.x0, rb[0]);
            L::storei(rect.y0, rb[1]);
            L::storei(rect.x1, rb[2]);
            L::storei(rect.y1, rb[3]);
        }
        F a[N], b[N];  // with transposes: each lane's Splat2D floats 0-7 (a) and 8-15 (b) as rows
        if constexpr (L::TRANSPOSES) {
            static_assert(offsetof(Splat2D, color) == 28 && offsetof(Splat2D, inv_sigma2) == 60 &&
                          offsetof(Splat2D, log_min_alpha) == 64);
            const F rows_a[N] = {out.xy[0],    out.xy[1],    out.depth,    out.opacity,
                                 out.conic[0], out.conic[1], out.conic[2], cols[7]};
            const F rows_b[N] = {color[6],   color[7],   out.v1[0],      out.v1[1],
                                 out.sigma1, out.sigma2, out.inv_sigma1, out.inv_sigma2};
            std::copy(rows_a, rows_a + N, a);
            std::copy(rows_b, rows_b + N, b);
            L::transpose(a);
            L::transpose(b);
        }
        for (int j = 0; j < count; ++j) {
            if (!((ok >> j) & 1u)) continue;
            const int64_t i = i0 + j;
            Splat2D& s = job.splats[i];
            if constexpr (L::TRANSPOSES) {
                L::store(a[j], &s.xy.x);
                L::store(b[j], &s.color[1]);
            } else {
                s.xy = Vec2{o[0][j], o[1][j]};
                s.depth = o[2][j];
                s.opacity = o[3][j];
                for (int c = 0; c < 3; ++c) s.conic[c] = o[4 + c][j];
                for (int c = 0; c < 3; ++c) s.color[c] = job.stage[i].color[c];  // on screen: computed by the stage
                s.v1 = Vec2{o[7][j], o[8][j]};
                s.sigma1 = o[9][j];
                s.sigma2 = o[10][j];
                s.inv_sigma1 = o[11][j];
                s.inv_sigma2 = o[12][j];
            }
            s.log_min_alpha = out.log_min_alpha(o[3][j]);
            s.radius = o[13][j];
            s.cell = job.cell_of ? job.cell_of[i] : -1;
            s.id = (int32_t)i;
            if (job.planes) {
                const SplatIn in{job.means + 3 * i,
                                 job.scales + 3 * i,
                                 job.quats + 4 * i,
                                 0.0f,
                                 nullptr,
                                 job.filter_3d ? job.filter_3d[i] : 0.0f,
                                 nullptr,
                                 0,
                                 -1};
                job.planes[i] = splat_popfree_plane(job.cam, in);
            }
            job.rects[i] = TileRect{rb[0][j], rb[1][j], rb[2][j], rb[3][j]};
        }
    }
}

}  // namespace gbv
