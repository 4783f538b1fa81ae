// The per-pixel sorted modes' finish (frame.h: finish_rays): each splat's ray data (gbv/ray3d.h), and for eval3d its
// splat and tile rectangle from the stage and its 3D footprint.
#include <cmath>

#include "frame.h"
#include "gbv/ray3d.h"

namespace gbv::cpu {
namespace {

// The tiles whose pixel centres may lie in the box of pixel offsets `box` about xy (ray_footprint's), widened by the
// rounding of the offset px - xy; 2: every tile.
TileRect footprint_tiles(Vec2 xy, int kind, const double box[4], int gx, int gy) {
    if (kind == 2) return {0, 0, gx, gy};
    if (kind == 0) return {0, 0, 0, 0};
    const double slack = 1e-6 * (std::fabs((double)xy.x) + std::fabs((double)xy.y));
    // pixel i's centre is i + 0.5, in tile floor(i / TILE)
    const auto lo = [](double v, int g) { return (int)std::fmin(std::fmax(std::floor((v - 0.5) / TILE), 0.0), g); };
    const auto hi = [](double v, int g) { return (int)std::fmin(std::fmax(std::floor((v - 0.5) / TILE) + 1, 0.0), g); };
    return {lo(xy.x + box[0] - slack, gx), lo(xy.y + box[2] - slack, gy), hi(xy.x + box[1] + slack, gx),
            hi(xy.y + box[3] + slack, gy)};
}

}  // namespace

void finish_rays(const SceneView& sc, const Stage& stage, Mode mode, FrameBuffers& buf, FrameRun& run) {
    const CameraParams& cam = stage.key.cam;
    const int gx = (cam.width + TILE - 1) / TILE, gy = (cam.height + TILE - 1) / TILE;
    const int64_t n = (int64_t)stage.splats.size();
    buf.rays.resize(n);
    const float min_scale = mode == STOPTHEPOP ? STOPTHEPOP_MIN_SCALE : 0.0f;
    constexpr int64_t BLOCK = 4096;
#pragma omp parallel for schedule(dynamic, 1)
    for (int64_t b = 0; b < (n + BLOCK - 1) / BLOCK; ++b) {
        if (run.cancelled()) continue;
        for (int64_t i = b * BLOCK; i < std::min(n, (b + 1) * BLOCK); ++i) {
            const bool eval3d = mode == EVAL3D;
            if (!(eval3d ? stage.valid[i] : buf.valid[i])) {
                if (eval3d) buf.valid[i] = 0, buf.rects[i] = {0, 0, 0, 0};
                continue;
            }
            const int64_t r = stage.rows.empty() ? i : stage.rows[i];  // a level-of-detail cut's row
            const bool node = r >= sc.n;
            const int64_t k = node ? r - sc.n : r;
            const float* filter = node ? sc.tree.filter_3d : sc.filter_3d;
            const float* means = node ? sc.tree.means : sc.means;
            const float* scales = node ? sc.tree.scales : sc.scales;
            const float* quats = node ? sc.tree.quats : sc.quats;
            RaySplat& ray = buf.rays[i];
            bool ok = ray_splat(cam, means + 3 * k, quats + 4 * k, scales + 3 * k, filter ? filter[k] : 0.0f,
                                min_scale, &ray);
            if (!eval3d) {  // stopthepop: the scalar finish's splat and rectangle; a degenerate ray drops the splat
                if (!ok) buf.valid[i] = 0, buf.rects[i] = {0, 0, 0, 0};
                continue;
            }
            const StageSplat& st = stage.splats[i];
            Splat2D& s = buf.splats[i];
            s = Splat2D{};
            s.xy = {st.xy[0], st.xy[1]};
            s.depth = st.depth;
            s.opacity = st.opacity;
            for (int c = 0; c < 3; ++c) s.color[c] = st.color[c];
            s.log_min_alpha = logf(MIN_ALPHA_3DGS / st.opacity);
            s.cell = -1;
            double box[4] = {0, 0, 0, 0};
            const int kind = ok && st.opacity >= MIN_ALPHA_3DGS ? ray_footprint(ray, s.log_min_alpha, box) : 0;
            const TileRect t = footprint_tiles(s.xy, kind, box, gx, gy);
            ok = t.x1 > t.x0 && t.y1 > t.y0;
            buf.valid[i] = ok;
            buf.rects[i] = ok ? t : TileRect{0, 0, 0, 0};
        }
    }
}

}  // namespace gbv::cpu
