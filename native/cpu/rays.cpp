// The per-pixel sorted modes' finish (frame.h: finish_rays), one splat after another through gbv/ray3d.h's
// finish_ray_splat.
#include <algorithm>
#include <type_traits>
#include <vector>

#include "frame.h"
#include "gbv/ray3d.h"
#include "gbv/resort.h"

namespace gbv::cpu {

void finish_rays(const SceneView& sc, const Stage& stage, Mode mode, FrameBuffers& buf, FrameRun& run) {
    const CameraParams& cam = stage.key.cam;
    const int gx = (cam.width + TILE - 1) / TILE, gy = (cam.height + TILE - 1) / TILE;
    const int64_t n = (int64_t)stage.splats.size();
    buf.rays.resize(n);
    constexpr int64_t BLOCK = 4096;
#pragma omp parallel for schedule(dynamic, 1)
    for (int64_t b = 0; b < (n + BLOCK - 1) / BLOCK; ++b) {
        if (run.cancelled()) continue;
        for (int64_t i = b * BLOCK; i < std::min(n, (b + 1) * BLOCK); ++i) {
            // eval3d replaces the finish (every splat of the stage); stopthepop keeps the scalar finish's survivors
            const bool eval3d = mode == EVAL3D;
            bool ok = eval3d ? stage.valid[i] : buf.valid[i];
            if (ok) {
                const int64_t r = stage.rows.empty() ? i : stage.rows[i];  // a level-of-detail cut's row
                const bool node = r >= sc.n;
                const int64_t k = node ? r - sc.n : r;
                const float* filter = node ? sc.tree.filter_3d : sc.filter_3d;
                const SplatIn in{(node ? sc.tree.means : sc.means) + 3 * k,
                                 (node ? sc.tree.scales : sc.scales) + 3 * k,
                                 (node ? sc.tree.quats : sc.quats) + 4 * k,
                                 0.0f,
                                 nullptr,
                                 filter ? filter[k] : 0.0f,
                                 nullptr,
                                 0,
                                 -1};
                TileRect rect = buf.rects[i];
                ok = finish_ray_splat(in, stage.splats[i], cam, mode, gx, gy, &buf.splats[i], &rect, &buf.rays[i]);
                if (eval3d) buf.splats[i].id = (int32_t)i;  // Splat2D::id, as the finish it replaces sets it
                buf.rects[i] = rect;
            }
            buf.valid[i] = ok;
            if (!ok) buf.rects[i] = {0, 0, 0, 0};
        }
    }
}

void tile_depth_order(const CameraParams& cam, int tx0, int ty0, int64_t count, Splat2D* list, SplatBounds* bounds,
                      RaySplat* rays, uint32_t* ids) {
    thread_local std::vector<std::pair<float, int64_t>> keyed;
    keyed.resize(count);
    for (int64_t j = 0; j < count; ++j)
        keyed[j] = {tile_depth_key(list[j], rays[j], tx0 + 0.5f, ty0 + 0.5f, cam.cx, cam.cy, cam.fx, cam.fy), j};
    std::stable_sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    const auto permute = [&](auto* a) {
        if (!a) return;
        thread_local std::vector<std::remove_pointer_t<decltype(a)>> tmp;
        tmp.assign(a, a + count);
        for (int64_t j = 0; j < count; ++j) a[j] = tmp[keyed[j].second];
    };
    permute(list);
    permute(bounds);
    permute(rays);
    permute(ids);
}

}  // namespace gbv::cpu
