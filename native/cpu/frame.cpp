// The frame driver (frame.h): pixel boxes, the parallel preprocess and blend, the partial frame, the pixel trace's
// frame.
#include <algorithm>
#include <cmath>
#include <limits>

#include "frame.h"
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
        for (int64_t i = b * BOX_BLOCK; i < std::min(n, (b + 1) * BOX_BLOCK); ++i) boxes[i] = splat_bounds(splats[i], mode);
    }
}

// Blend: each tile copies its splats (and their boxes) into contiguous per-thread buffers, then the selected SIMD
// path blends its pixels in lane groups.
void blend_tiles(const std::vector<Splat2D>& splats, const std::vector<int64_t>& tile_start,
                 const std::vector<uint64_t>& keys, const CameraParams& cam, Mode mode, const OitParams& oit,
                 const float bg[3], BlendTileFn blend_tile, std::vector<SplatBounds>& boxes, Image& img, Stats& st,
                 FrameRun& run, int N) {
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE;
    const int num_tiles = (int)tile_start.size() - 1;
    const std::vector<int> order = centre_out_order(gx, num_tiles / gx);
    auto t0 = Clock::now();
    splat_boxes(splats, mode, boxes, run);
    TileJob frame = {};  // what every tile shares; each tile sets its list, rectangle and planes
    frame.width = W;
    frame.mode = mode;
    frame.oit = oit;
    for (int c = 0; c < 3; ++c) frame.bg[c] = bg[c];
#pragma omp parallel
    {
        FlushDenormals ftz;
        std::vector<Splat2D> local;
        std::vector<SplatBounds> bounds;
#pragma omp for schedule(dynamic, 1)
        for (int i = 0; i < num_tiles; ++i) {
            if (run.cancelled()) continue;  // a cancelled frame skips its remaining tiles
            const int t = order[i];
            const int64_t begin = tile_start[t], count = tile_start[t + 1] - begin;
            local.resize(count);
            bounds.resize(count);
            for (int64_t j = 0; j < count; ++j) {
                const uint32_t id = (uint32_t)keys[begin + j];
                local[j] = splats[id];
                bounds[j] = boxes[id];
            }
            TileJob job = frame;
            job.list = local.data();
            job.bounds = bounds.data();
            job.n = (int)count;
            job.x0 = (t % gx) * TILE;
            job.y0 = (t / gx) * TILE;
            job.x1 = std::min(job.x0 + TILE, W);
            job.y1 = std::min(job.y0 + TILE, H);
            const size_t origin = (size_t)job.y0 * W + job.x0;
            job.rgb = img.rgb.data() + origin * 3;
            job.alpha = img.alpha.data() + origin;
            job.window = img.window.empty() ? nullptr : img.window.data() + origin * 2;
            job.evals = img.evals.data() + origin;
            blend_tile(job);
            if (run.partial()) write_partial(img, N, job.x0, job.y0, job.x1, job.y1, run.partial());
            run.tile_done();
            run.poll();
        }
    }
    st.blend_ms += ms_since(t0);
}

constexpr int64_t PREPROCESS_BLOCK = 256;  // splats per call of a path's preprocess (a multiple of 16)

}  // namespace

void bin_frame(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
               const simd::Path& path, FrameBuffers& buf, Stats& st, FrameRun& run) {
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE;
    const int num_tiles = gx * gy;
    const int64_t n = sc.n;
    run.start(num_tiles);

    auto t0 = Clock::now();
    // every element of the reused buffers is written before it is read; a much smaller scene releases them
    if ((size_t)n < buf.splats.capacity() / 4) buf = FrameBuffers();
    std::vector<Splat2D>& splats = buf.splats;
    std::vector<TileRect>& rects = buf.rects;
    std::vector<uint8_t>& valid = buf.valid;
    splats.resize(n);
    rects.resize(n);
    valid.resize(n);
    // in blocks of PREPROCESS_BLOCK splats through the SIMD path's preprocess (bit-identical on every path)
    PreprocessJob job{sc.means, sc.scales, sc.quats, sc.opacities, sc.sh, sc.filter_3d, sc.k, sc.weight_sh,
                      sc.weight_k, mode == DUPLEX ? sc.cell_of.data() : nullptr, sh_deg, cam, mode, oit, gx, gy,
                      splats.data(), rects.data(), valid.data()};
    const int64_t blocks = (n + PREPROCESS_BLOCK - 1) / PREPROCESS_BLOCK;
#pragma omp parallel for schedule(static)
    for (int64_t b = 0; b < blocks; ++b) {
        if (run.cancelled()) continue;  // a cancelled frame stops here too, not only between tiles
        path.preprocess(job, b * PREPROCESS_BLOCK, std::min(n, (b + 1) * PREPROCESS_BLOCK));
        run.poll();
    }
    if (run.cancelled()) return;
    if (testing::capture.load(std::memory_order_relaxed))
        testing::record_preprocess(splats.data(), rects.data(), valid.data(), n);
    st.preprocess_ms += ms_since(t0);

    std::vector<int64_t>& tile_start = buf.tile_start;
    std::vector<uint64_t>& keys = buf.keys;  // per tile list entry: splat id in the low 32 bits
    tile_start.assign(num_tiles + 1, 0);
    if (mode == DUPLEX) {
        bin_duplex(sc, cam, splats, rects, valid, gx, gy, tile_start, keys, st, run);
    } else if (mode == WSR) {  // order-independent: the splat order
        bin_splats(splats, rects, valid, nullptr, n, gx, tile_start, keys, st, run);
    } else {
        t0 = Clock::now();
        depth_order(splats, valid, buf.order, buf.order_scratch, run);
        if (run.cancelled()) return;
        st.sort_ms += ms_since(t0);
        st.sort_length += (int64_t)buf.order.size();
        bin_splats(splats, rects, valid, buf.order.data(), (int64_t)buf.order.size(), gx, tile_start, keys, st, run);
    }
    if (run.cancelled()) return;
    if (keys.capacity() > 4 * keys.size() + (1u << 20)) keys.shrink_to_fit();  // after a much larger frame
    if (testing::capture.load(std::memory_order_relaxed)) testing::record_lists(tile_start, keys);
}

void render_image(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
                  const float bg[3], const simd::Path& path, FrameBuffers& buf, Image& img, Stats& st, FrameRun& run,
                  int N) {
    bin_frame(sc, cam, mode, oit, sh_deg, path, buf, st, run);
    if (run.cancelled()) return;
    blend_tiles(buf.splats, buf.tile_start, buf.keys, cam, mode, oit, bg, path.blend_tile, buf.boxes, img, st, run,
                N);
}

PixelTrace trace_frame_pixel(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int sh_deg, const float bg[3], const simd::Path& path, FrameBuffers& buf, int x, int y,
                             int N) {
    Stats st;
    const Control none;
    FrameRun run(none);
    bin_frame(sc, cam, mode, oit, sh_deg, path, buf, st, run);
    splat_boxes(buf.splats, mode, buf.boxes, run);
    FrameLists lists = {buf.splats.data(), buf.boxes.data(), buf.tile_start.data(), buf.keys.data(), cam.width,
                        cam.height, mode, oit, {bg[0], bg[1], bg[2]}};
    FlushDenormals ftz;
    return trace_pixel(lists, x, y, N);
}

}  // namespace gbv::cpu
