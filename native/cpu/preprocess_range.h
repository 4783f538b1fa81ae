// The CPU's preprocess of a range of splats, written once over a lane type L (gbv/lanes.h): Lanes1 calls
// preprocess_splat one splat at a time (the scalar path, blend_scalar.cpp); a vector lane type (preprocess_isa.cpp,
// once per instruction set) moves L::N splats' inputs into lanes, runs the same preprocess_splat<L> on all of them and
// writes each lane's Splat2D, TileRect and flag: bit-identical to one splat at a time (preprocess.h).
#pragma once

#include <cstdint>

#include "gbv/preprocess.h"

namespace gbv {

// One frame's preprocess: the scene (activated parameters, gbviewer.Scene's layout), the camera and mode, and the
// per-splat outputs. Plain data, shared by the translation units of every instruction set.
struct PreprocessJob {
    const float *means, *scales, *quats, *opacities, *sh, *filter_3d;  // filter_3d may be null
    int k;                     // SH coefficients per channel
    const float* weight_sh;    // (n, weight_k) or null
    int weight_k;
    const int32_t* cell_of;    // duplex: each splat's cell; null: -1
    int sh_deg;
    CameraParams cam;
    Mode mode;
    OitParams oit;
    int grid_x, grid_y;
    Splat2D* splats;
    TileRect* rects;
    uint8_t* valid;
};

// Preprocess splats [begin, end) of the job.
using PreprocessFn = void (*)(const PreprocessJob& job, int64_t begin, int64_t end);

template <class L>
void preprocess_range(const PreprocessJob& job, int64_t begin, int64_t end) {
    const int weight_deg = sh_degree_for_coeffs(job.weight_k);
    if constexpr (L::N == 1) {
        for (int64_t i = begin; i < end; ++i) {
            SplatIn in{job.means + 3 * i, job.scales + 3 * i, job.quats + 4 * i, job.opacities[i],
                       job.sh + (size_t)job.k * 3 * i, job.filter_3d ? job.filter_3d[i] : 0.0f,
                       job.weight_sh ? job.weight_sh + (size_t)job.weight_k * i : nullptr, weight_deg,
                       job.cell_of ? job.cell_of[i] : -1};
            job.valid[i] = preprocess_splat(in, job.sh_deg, job.cam, job.mode, job.oit, job.grid_x, job.grid_y,
                                            &job.splats[i], &job.rects[i]);
        }
    } else {
        using F = typename L::F;
        constexpr int N = L::N;
        const bool oit = job.mode == WSR || job.mode == DUPLEX;
        const int nsh = (job.sh_deg + 1) * (job.sh_deg + 1) * 3;  // coefficients sh_to_rgb reads
        const int wdeg = job.sh_deg < weight_deg ? job.sh_deg : weight_deg;
        const int nw = oit && job.weight_sh ? (wdeg + 1) * (wdeg + 1) : 0;  // ... and sh_to_weight
        alignas(64) float buf[16][N];  // means, scales, quats, opacity, filter_3d
        alignas(64) float shb[48][N], wb[16][N];
        alignas(64) float o[17][N];
        alignas(64) int32_t rb[4][N];
        F sh[48], w[16];
        for (int64_t i0 = begin; i0 < end; i0 += N) {
            const int count = end - i0 < N ? (int)(end - i0) : N;
            for (int j = 0; j < N; ++j) {
                const int64_t i = i0 + (j < count ? j : count - 1);  // spare lanes repeat the last splat
                for (int c = 0; c < 3; ++c) buf[c][j] = job.means[3 * i + c];
                for (int c = 0; c < 3; ++c) buf[3 + c][j] = job.scales[3 * i + c];
                for (int c = 0; c < 4; ++c) buf[6 + c][j] = job.quats[4 * i + c];
                buf[10][j] = job.opacities[i];
                buf[11][j] = job.filter_3d ? job.filter_3d[i] : 0.0f;
                const float* s = job.sh + (size_t)job.k * 3 * i;
                for (int q = 0; q < nsh; ++q) shb[q][j] = s[q];
                if (nw > 0) {
                    const float* ws = job.weight_sh + (size_t)job.weight_k * i;
                    for (int q = 0; q < nw; ++q) wb[q][j] = ws[q];
                }
            }
            SplatInLanes<L> in;
            for (int c = 0; c < 3; ++c) in.mean[c] = L::load(buf[c]);
            for (int c = 0; c < 3; ++c) in.scale[c] = L::load(buf[3 + c]);
            for (int c = 0; c < 4; ++c) in.quat[c] = L::load(buf[6 + c]);
            in.opacity = L::load(buf[10]);
            in.filter_3d = L::load(buf[11]);
            for (int q = 0; q < nsh; ++q) sh[q] = L::load(shb[q]);
            for (int q = 0; q < nw; ++q) w[q] = L::load(wb[q]);
            in.sh = sh;
            in.weight_sh = job.weight_sh ? w : nullptr;
            in.weight_deg = weight_deg;
            Splat2DLanes<L> out;
            TileRectLanes<L> rect;
            const uint32_t ok = L::bits(preprocess_splat<L>(in, job.sh_deg, job.cam, job.mode, job.oit,
                                                            job.grid_x, job.grid_y, &out, &rect));
            for (int j = 0; j < count; ++j) job.valid[i0 + j] = (ok >> j) & 1u;
            if (!ok) continue;
            const F fields[17] = {out.xy[0], out.xy[1], out.depth, out.opacity, out.conic[0], out.conic[1],
                                  out.conic[2], out.color[0], out.color[1], out.color[2], out.v1[0], out.v1[1],
                                  out.sigma1, out.sigma2, out.inv_sigma1, out.inv_sigma2, out.radius};
            for (int f = 0; f < 17; ++f) L::store(fields[f], o[f]);
            L::storei(rect.x0, rb[0]);
            L::storei(rect.y0, rb[1]);
            L::storei(rect.x1, rb[2]);
            L::storei(rect.y1, rb[3]);
            for (int j = 0; j < count; ++j) {
                if (!((ok >> j) & 1u)) continue;
                const int64_t i = i0 + j;
                Splat2D& s = job.splats[i];
                s.xy = Vec2{o[0][j], o[1][j]};
                s.depth = o[2][j];
                s.opacity = o[3][j];
                s.log_min_alpha = out.log_min_alpha(o[3][j]);
                for (int c = 0; c < 3; ++c) s.conic[c] = o[4 + c][j];
                for (int c = 0; c < 3; ++c) s.color[c] = o[7 + c][j];
                s.v1 = Vec2{o[10][j], o[11][j]};
                s.sigma1 = o[12][j];
                s.sigma2 = o[13][j];
                s.inv_sigma1 = o[14][j];
                s.inv_sigma2 = o[15][j];
                s.radius = o[16][j];
                s.cell = job.cell_of ? job.cell_of[i] : -1;
                job.rects[i] = TileRect{rb[0][j], rb[1][j], rb[2][j], rb[3][j]};
            }
        }
    }
}

}  // namespace gbv
