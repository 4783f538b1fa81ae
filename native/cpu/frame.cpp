// The frame driver (frame.h): pixel boxes, the parallel stage, finish and joint blend, the partial frame, the pixel
// trace's frame.
#include <algorithm>
#include <cmath>
#include <limits>

#include "blend_bands.h"
#include "blend_sorted.h"
#include "frame.h"
#include "lod.h"
#include "plane.h"
#include "testing.h"

namespace gbv::cpu {
namespace {

// Box a splat's SplatBounds span (blend_tile skips a lane group whose box misses it, without evaluating the splat).
// scalar, mip, wsr, duplex: the pixel centres where the splat can pass its cut-off, the ellipse power >=
// log_min_alpha, i.e. d^T conic d <= r2 with r2 = -2 log_min_alpha, whose half-extents are sqrt(r2 Sigma_xx) and
// sqrt(r2 Sigma_yy) (Sigma = conic^-1), computed in double and widened for float rounding: the float power at a pixel
// is off by at most ~4 ulp of conic-weighted |d|^2, i.e. a relative 2.4e-7 (lambda_max / lambda_min) of r2 at the
// ellipse, so the box grows by 1e-6 kappa^2 + 1e-5 relative plus 0.01 px (the rounding of d = xy - pixel). duplex
// also has its radius circle. gaussian_blending: gaussian_blending_bounds (blend_tile.h; the group box adds the
// half perimeters). analytic (alpha integrated over the pixel): no box.

SplatBounds splat_bounds(const Splat2D& s, Mode mode) {
    constexpr float inf = std::numeric_limits<float>::infinity();
    if (mode == ANALYTIC || !testing::pixel_boxes.load(std::memory_order_relaxed)) return {-inf, inf, -inf, inf};
    if (mode == GAUSSIAN_BLENDING) return gaussian_blending_bounds(s);
    const double a = s.conic[0], b = s.conic[1], c = s.conic[2];
    const double det = a * c - b * b;
    const double r2 = -2.0 * (double)s.log_min_alpha;
    const double kappa = (double)s.sigma1 / (double)s.sigma2;
    if (!(det > 0.0) || !(r2 >= 0.0) || !std::isfinite(kappa)) return {-inf, inf, -inf, inf};
    const double grow = 1.0 + 1e-6 * kappa * kappa + 1e-5;
    double ex = std::sqrt(r2 * c / det) * grow + 0.01, ey = std::sqrt(r2 * a / det) * grow + 0.01;
    if (mode == DUPLEX) {
        ex = std::min(ex, (double)s.radius + 0.01);
        ey = std::min(ey, (double)s.radius + 0.01);
    }
    if (!std::isfinite(ex) || !std::isfinite(ey)) return {-inf, inf, -inf, inf};
    return {(float)(s.xy.x - ex), (float)(s.xy.x + ex), (float)(s.xy.y - ey), (float)(s.xy.y + ey)};
}

// Copy a finished tile [x0, x1) x [y0, y1) of `img` (N x N samples per output pixel) into the partial frame
// (output pixels, RGB). With N > 1 a pixel whose samples straddle tiles gets the mean of this tile's samples; the
// final frame replaces it.
void write_partial(const Image& img, int N, int x0, int y0, int x1, int y1, float* partial) {
    const int out_w = img.width / N;
    for (int oy = y0 / N; oy <= (y1 - 1) / N; ++oy) {
        for (int ox = x0 / N; ox <= (x1 - 1) / N; ++ox) {
            float acc[3] = {0, 0, 0};
            int count = 0;
            for (int y = std::max(y0, oy * N); y < std::min(y1, oy * N + N); ++y) {
                for (int x = std::max(x0, ox * N); x < std::min(x1, ox * N + N); ++x, ++count) {
                    for (int c = 0; c < 3; ++c) acc[c] += img.rgb[((size_t)y * img.width + x) * 3 + c];
                }
            }
            const float inv = 1.0f / count;  // as box_downsample rounds
            for (int c = 0; c < 3; ++c) partial[((size_t)oy * out_w + ox) * 3 + c] = acc[c] * inv;
        }
    }
}

// Tiles from the image centre outwards: a refining frame fills in where the eye is first (and the central tiles,
// usually the busiest, start first, which also balances the dynamic schedule).
std::vector<int> centre_out_order(int gx, int gy) {
    std::vector<int> order(gx * gy);
    std::vector<float> dist(gx * gy);
    for (int t = 0; t < gx * gy; ++t) {
        const float dx = (t % gx) + 0.5f - gx * 0.5f, dy = (t / gx) + 0.5f - gy * 0.5f;
        dist[t] = dx * dx + dy * dy;
        order[t] = t;
    }
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return dist[a] < dist[b]; });
    return order;
}

constexpr int64_t BOX_BLOCK = 4096;  // splats between two cancel checks of splat_boxes

// Every splat's SplatBounds in `mode` (stops early once cancelled).
void splat_boxes(const std::vector<Splat2D>& splats, Mode mode, std::vector<SplatBounds>& boxes, FrameRun& run) {
    const int64_t n = (int64_t)splats.size();
    boxes.resize(n);
#pragma omp parallel for schedule(static)
    for (int64_t b = 0; b < (n + BOX_BLOCK - 1) / BOX_BLOCK; ++b) {
        if (run.cancelled()) continue;
        for (int64_t i = b * BOX_BLOCK; i < std::min(n, (b + 1) * BOX_BLOCK); ++i)
            boxes[i] = splat_bounds(splats[i], mode);
    }
}

// One tile of one frame (blend_frames): copy its splats (and their boxes) into contiguous per-thread buffers, then
// the selected SIMD path blends its pixels in lane groups.
void blend_one_tile(const BlendFrame& f, const TileJob& shared, int t, BlendTileFn blend_tile, Plane<Splat2D>& local,
                    Plane<SplatBounds>& bounds, Plane<RaySplat>& rays, Bands& bands, float* partial) {
    const TileRegion& reg = f.reg;
    const int gx = reg.gx();
    const FrameBuffers& b = *f.buf;
    const int64_t begin = b.tile_start[t], count = b.tile_start[t + 1] - begin;
    local.resize(count);
    bounds.resize(count);
    constexpr int64_t AHEAD = 8;  // the list's splats are scattered over the frame's: fetch them ahead of the copy
    for (int64_t j = 0; j < count; ++j) {
        if (j + AHEAD < count) {
            const uint32_t next = b.ids[begin + j + AHEAD];
            __builtin_prefetch(&b.splats[next]);
            __builtin_prefetch((const char*)&b.splats[next] + sizeof(Splat2D) - 1);
            __builtin_prefetch(&b.boxes[next]);
        }
        const uint32_t id = b.ids[begin + j];
        local[j] = b.splats[id];
        bounds[j] = b.boxes[id];
    }
    TileJob job = shared;
    job.x0 = reg.x0 + (t % gx) * TILE;  // the whole image's pixel coordinates
    job.y0 = reg.y0 + (t / gx) * TILE;
    job.tile_x0 = job.x0;
    job.tile_y0 = job.y0;
    const bool sorted = per_pixel_sorted(f.mode);
    if (sorted) {
        rays.resize(count);
        for (int64_t j = 0; j < count; ++j) rays[j] = b.rays[b.ids[begin + j]];
        if (f.mode == STOPTHEPOP && f.queue > 0) {
            tile_depth_order(*f.cam, job.x0, job.y0, count, local.data(), bounds.data(), rays.data(), nullptr);
            thread_local tile::HierCache hier;
            hier.reset();
            job.hier = &hier;
        }
        blend_tile = blend_tile_scalar;  // one pixel at a time on every path (blend_sorted.h)
    }
    job.list = local.data();
    job.bounds = bounds.data();
    job.rays = sorted ? rays.data() : nullptr;
    job.n = (int)count;
    job.x1 = std::min(job.x0 + TILE, reg.x1);
    job.y1 = std::min(job.y0 + TILE, reg.y1);
    // gaussian_blending's group box starts 1.001 px about the row and moves with its windows: a wider band (2 px)
    const float margin =
        f.mode == GAUSSIAN_BLENDING ? testing::gaussian_band_margin.load(std::memory_order_relaxed) : 0.0f;
    const bool banded = testing::row_bands.load(std::memory_order_relaxed) &&
                        build_bands(job.bounds, job.n, job.y0, job.y1 - job.y0, job.group_rows, margin, bands);
    job.bands = banded ? &bands : nullptr;
    Image& img = *f.img;
    const size_t origin = (size_t)(job.y0 - reg.y0) * (reg.x1 - reg.x0) + (job.x0 - reg.x0);
    job.rgb = img.rgb.data() + origin * 3;
    job.alpha = img.alpha.data() + origin;
    job.window = img.window.empty() ? nullptr : img.window.data() + origin * 2;
    job.evals = img.evals.data() + origin;
    blend_tile(job);
    if (partial) write_partial(img, f.N, job.x0 - reg.x0, job.y0 - reg.y0, job.x1 - reg.x0, job.y1 - reg.y0, partial);
}

// Each splat's tile rectangle (of the whole image's grid) within the region's tiles, in the region's tile
// coordinates; empty (0, 0, 0, 0, as a splat that is not valid) where it misses them.
void clip_rects(std::vector<TileRect>& rects, const TileRegion& reg, FrameRun& run) {
    const int tx = reg.x0 / TILE, ty = reg.y0 / TILE, gx = reg.gx(), gy = reg.gy();
    const int64_t n = (int64_t)rects.size();
#pragma omp parallel for schedule(static)
    for (int64_t b = 0; b < (n + BOX_BLOCK - 1) / BOX_BLOCK; ++b) {
        if (run.cancelled()) continue;
        for (int64_t i = b * BOX_BLOCK; i < std::min(n, (b + 1) * BOX_BLOCK); ++i) {
            TileRect& r = rects[i];
            const TileRect c{std::max(r.x0 - tx, 0), std::max(r.y0 - ty, 0), std::min(r.x1 - tx, gx),
                             std::min(r.y1 - ty, gy)};
            r = c.x1 > c.x0 && c.y1 > c.y0 ? c : TileRect{0, 0, 0, 0};
        }
    }
}

constexpr int64_t PREPROCESS_BLOCK = 256;  // splats per call of a path's stage or finish (a multiple of 16)

// fn(begin, end) over the blocks of n splats in parallel; a cancelled frame stops here too, not only between tiles.
// Handed out BLOCKS_PER_GRAB at a time: a level-of-detail cut's rows cost unevenly (scattered leaves, then denser
// interior nodes), and halves fixed in advance leave one core waiting.
constexpr int BLOCKS_PER_GRAB = 8;
template <class Fn>
void for_blocks(int64_t n, FrameRun& run, Fn fn) {
    const int64_t blocks = (n + PREPROCESS_BLOCK - 1) / PREPROCESS_BLOCK;
#pragma omp parallel for schedule(dynamic, BLOCKS_PER_GRAB)
    for (int64_t b = 0; b < blocks; ++b) {
        if (run.cancelled()) continue;
        fn(b * PREPROCESS_BLOCK, std::min(n, (b + 1) * PREPROCESS_BLOCK));
        run.poll();
    }
}

}  // namespace

// The level-of-detail cut of `key` (lod.h) as the stage's rows and weights: drawn leaves (scene rows, in the cut's
// order) first, then drawn interior nodes (rows n_scene + node, ascending), the order gbviewer.lod.cut_scene gathers
// them in. False, and no rows, for a cut that is the scene's leaves (drawn as the scene itself, bit for bit). Stops
// early once `run` is cancelled (the rows then unspecified: the stage is not ready).
bool cut_rows(const SceneView& sc, const LodArgs& a, Stage& stage, FrameRun& run) {
    const SceneView::Hierarchy& t = sc.tree;
    const lod::View view{{a.eye[0], a.eye[1], a.eye[2]}, a.focal, a.orthographic};
    lod::Cut c = lod::cut(t.means, t.radius, t.size, t.levels, t.num_levels, t.order, view, a.tau, a.band,
                          (int32_t)sc.n, 0, [&run] { return run.cancelled(); });
    stage.rows.clear();
    stage.weights.clear();
    if (c.stopped || ((int64_t)c.rows.size() == sc.n && c.leaves == sc.n)) return false;  // (a stop: not ready)
    stage.rows = std::move(c.rows);
    stage.weights = std::move(c.weights);
    return true;  // an empty cut (a root whose size is not a number) draws nothing, as cut_scene's gather
}

void build_stage(const SceneView& sc, const StageKey& key, const simd::Path& path, Stage& stage, Stats& st,
                 FrameRun& run) {
    const Clock::time_point t0 = Clock::now();
    if ((size_t)sc.n < stage.splats.capacity() / 4) stage = Stage();  // a much smaller scene releases the storage
    stage.key = key;
    stage.ready = stage.order_ready = false;
    stage.rows.clear();
    stage.weights.clear();
    const bool cut = key.lod.on() && cut_rows(sc, key.lod, stage, run);
    if (run.cancelled()) return;  // not ready
    const int64_t n = cut ? (int64_t)stage.rows.size() : sc.n;
    stage.splats.resize(n);
    stage.valid.resize(n);
    stage.depth.resize(n);
    const CameraParams& cam = key.cam;
    StageJob job{sc.means,
                 sc.scales,
                 sc.quats,
                 sc.opacities,
                 sc.sh,
                 sc.filter_3d,
                 sc.k,
                 key.sh_deg,
                 cam,
                 key.reach,
                 key.rules,
                 (cam.width + TILE - 1) / TILE,
                 (cam.height + TILE - 1) / TILE,
                 stage.splats.data(),
                 stage.valid.data(),
                 stage.depth.data()};
    job.n_scene = sc.n;
    if (cut) {
        const SceneView::Hierarchy& t = sc.tree;
        job.rows = stage.rows.data();
        job.weights = stage.weights.data();
        job.node_means = t.means, job.node_scales = t.scales, job.node_quats = t.quats;
        job.node_opacities = t.opacities, job.node_sh = t.sh, job.node_filter_3d = t.filter_3d;
    }
    for_blocks(n, run, [&](int64_t begin, int64_t end) { path.stage(job, begin, end); });
    stage.ready = !run.cancelled();
    const double ms = ms_since(t0);
    st.stage_ms += ms;
    st.preprocess_ms += ms;
}

void bin_frame(const SceneView& sc, Stage& stage, Mode mode, const OitParams& oit, const simd::Path& path,
               FrameBuffers& buf, Stats& st, FrameRun& run, const TileRegion& reg) {
    const CameraParams& cam = stage.key.cam;
    const int full_gx = (cam.width + TILE - 1) / TILE, full_gy = (cam.height + TILE - 1) / TILE;
    const int64_t n = (int64_t)stage.splats.size();  // the scene's splats, or a level-of-detail cut's
    if (stage.key.lod.on()) st.lod_drawn = n;
    Clock::time_point t0 = Clock::now();
    // every element of the reused buffers is written before it is read; a much smaller scene releases them (not a
    // level-of-detail cut of this one: the viewer's previews would free what its next full frame allocates again)
    if ((size_t)sc.n < buf.splats.capacity() / 4) buf = FrameBuffers();
    std::vector<Splat2D>& splats = buf.splats;
    std::vector<TileRect>& rects = buf.rects;
    std::vector<uint8_t>& valid = buf.valid;
    splats.resize(n);
    rects.resize(n);
    valid.resize(n);
    buf.planes.resize(mode == STOCHASTIC_POPFREE ? n : 0);
    // in blocks of PREPROCESS_BLOCK splats through the SIMD path's finish (bit-identical on every path)
    const FinishJob job{sc.means,
                        sc.scales,
                        sc.quats,
                        sc.filter_3d,
                        sc.weight_sh,
                        sc.weight_k,
                        mode == DUPLEX ? sc.cell_of.data() : nullptr,
                        stage.key.sh_deg,
                        cam,
                        mode,
                        oit,
                        full_gx,
                        full_gy,
                        stage.splats.data(),
                        stage.valid.data(),
                        splats.data(),
                        rects.data(),
                        valid.data(),
                        mode == STOCHASTIC_POPFREE ? buf.planes.data() : nullptr};
    if (mode != EVAL3D) for_blocks(n, run, [&](int64_t begin, int64_t end) { path.finish(job, begin, end); });
    if (per_pixel_sorted(mode) && !run.cancelled()) finish_rays(sc, stage, mode, buf, run);
    if (run.cancelled()) return;
    if (testing::capture.load(std::memory_order_relaxed))
        testing::record_preprocess(splats.data(), rects.data(), valid.data(), n);
    st.preprocess_ms += ms_since(t0);
    const int gx = reg.gx(), gy = reg.gy();
    if (gx != full_gx || gy != full_gy) clip_rects(rects, reg, run);

    std::vector<int64_t>& tile_start = buf.tile_start;
    std::vector<uint32_t>& ids = buf.ids;
    tile_start.assign(gx * gy + 1, 0);
    if (mode == DUPLEX) {
        bin_duplex(sc, cam, splats, rects, valid, gx, gy, tile_start, ids, st, run);
    } else if (mode == WSR) {  // order-independent: the splat order
        bin_splats(rects, nullptr, n, gx, tile_start, ids, buf.ranked, st, run);
    } else {
        if (!stage.order_ready) {  // once per stage: every later frame of this camera bins in it
            t0 = Clock::now();
            depth_order(stage.depth, stage.order, stage.order_scratch, run);
            if (run.cancelled()) return;
            stage.order_ready = true;
            st.order_ms += ms_since(t0);
            st.sort_ms += ms_since(t0);
        } else {
            st.order_reused = true;
        }
        st.sort_length += (int64_t)stage.order.size();
        bin_splats(rects, stage.order.data(), (int64_t)stage.order.size(), gx, tile_start, ids, buf.ranked, st, run);
    }
    if (run.cancelled()) return;
    if (ids.capacity() > 4 * ids.size() + (1u << 20)) ids.shrink_to_fit();  // after a much larger frame
    if (testing::capture.load(std::memory_order_relaxed))
        testing::record_lists(tile_start, ids, splats, mode != DUPLEX);
}

void blend_frames(const std::vector<BlendFrame>& frames, BlendTileFn blend_tile, FrameRun& run) {
    const Clock::time_point t0 = Clock::now();
    std::vector<TileJob> shared(frames.size());  // what every tile of a frame shares; each tile sets its own
    std::vector<std::pair<double, std::pair<int, int>>> tiles;  // (fraction of its frame, (frame, tile))
    for (size_t f = 0; f < frames.size(); ++f) {
        const BlendFrame& fr = frames[f];
        splat_boxes(fr.buf->splats, fr.mode, fr.buf->boxes, run);
        TileJob& job = shared[f];
        job = {};
        job.width = fr.reg.x1 - fr.reg.x0;
        job.mode = fr.mode;
        job.oit = fr.oit;
        job.frame_key = fr.frame_key;
        job.fast = fr.fast;
        job.group_rows =
            fr.fast && fr.mode == GAUSSIAN_BLENDING && blend_tile != blend_tile_scalar ? FAST_GB_GROUP_ROWS : 1;
        job.planes = fr.buf->planes.empty() ? nullptr : fr.buf->planes.data();
        job.queue = fr.queue;
        for (int c = 0; c < 3; ++c) job.bg[c] = fr.bg[c];
        const int gx = fr.reg.gx();
        const int num_tiles = (int)fr.buf->tile_start.size() - 1;
        const std::vector<int> order = centre_out_order(gx, num_tiles / gx);
        for (int i = 0; i < num_tiles; ++i) tiles.push_back({(i + 0.5) / num_tiles, {(int)f, order[i]}});
    }
    std::stable_sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
#pragma omp parallel
    {
        FlushDenormals ftz;
        Plane<Splat2D> local;  // each tile's entries are copied in before they are read
        Plane<SplatBounds> bounds;
        Plane<RaySplat> rays;
        Bands bands;
#pragma omp for schedule(dynamic, 1)
        for (int64_t i = 0; i < (int64_t)tiles.size(); ++i) {
            if (run.cancelled()) continue;  // a cancelled call skips its remaining tiles
            const int f = tiles[i].second.first;
            blend_one_tile(frames[f], shared[f], tiles[i].second.second, blend_tile, local, bounds, rays, bands,
                           run.partial(f));
            run.tile_done(f);
            run.poll();
        }
    }
    const double ms = ms_since(t0);
    for (const BlendFrame& fr : frames) fr.st->blend_ms += ms;
}

PixelTrace trace_frame_pixel(const SceneView& sc, Stage& stage, Mode mode, const OitParams& oit, int queue,
                             uint32_t frame_key, bool fast, const float bg[3], const simd::Path& path,
                             FrameBuffers& buf, int x, int y, int N) {
    Stats st;
    const Control none;
    FrameRun run(none, 1);
    bin_frame(sc, stage, mode, oit, path, buf, st, run, TileRegion::whole(stage.key.cam));
    splat_boxes(buf.splats, mode, buf.boxes, run);
    const CameraParams& cam = stage.key.cam;
    FrameLists lists = {buf.splats.data(),
                        buf.boxes.data(),
                        buf.tile_start.data(),
                        buf.ids.data(),
                        per_pixel_sorted(mode) ? buf.rays.data() : nullptr,
                        cam.width,
                        cam.height,
                        mode,
                        oit,
                        queue,
                        {bg[0], bg[1], bg[2]},
                        frame_key,
                        buf.planes.empty() ? nullptr : buf.planes.data(),
                        fast,
                        &cam};
    FlushDenormals ftz;
    return trace_pixel(lists, x, y, N);
}

}  // namespace gbv::cpu
