// CPU driver: preprocess (parallel over blocks of splats, in vector lanes), per-tile binning and depth sort, blending
// (parallel over tiles, dynamic schedule). The math is in include/gbv/*.h, shared with CUDA.
#include <omp.h>
#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>
#include <cmath>
#include <limits>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "blend_tile.h"
#include "image.h"
#include "trace.h"
#include "gbv/camera.h"
#include "gbv/order.h"
#include "gbv/preprocess.h"
#include "../bindings/nb_common.h"
#include <nanobind/stl/array.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>
#include "simd.h"

namespace nb = nanobind;
using namespace gbv;
using namespace gbv::nbc;
using LArr = nb::ndarray<int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;  // writable, shared with Python
using PArr = nb::ndarray<float, nb::ndim<3>, nb::c_contig, nb::device::cpu>;    // a partial frame, written here

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// A render's control block, shared with Python (render(..., control=int64[3])): [0] cancel flag (Python sets it),
// [1] tiles blended so far, [2] tiles in the frame (both written here). Relaxed atomics: only counts and a flag.
// `partial` (render(..., partial=float32[H][W][3]), or null) receives each finished tile's output pixels at once, so
// the caller can show a frame while it refines.
struct Progress {
    int64_t* ctl = nullptr;
    float* partial = nullptr;
    bool cancelled() const { return ctl && __atomic_load_n(&ctl[0], __ATOMIC_RELAXED) != 0; }
    void start(int64_t tiles) const {
        if (ctl) __atomic_store_n(&ctl[2], tiles, __ATOMIC_RELAXED);
    }
    void tile_done() const {
        if (ctl) __atomic_fetch_add(&ctl[1], 1, __ATOMIC_RELAXED);
    }
};

struct SceneView {
    const float *means, *scales, *quats, *opacities, *sh, *filter_3d;
    int64_t n;
    int k;  // SH coefficients per channel
    const float* weight_sh = nullptr;  // (n, weight_k) sort-free view-weight SH, or null
    int weight_k = 0;
    // Duplex cells: cell c holds the splats members[offsets[c] .. offsets[c+1]); cell_of[i] is splat i's cell.
    const float *cell_means = nullptr, *cell_scales = nullptr, *cell_quats = nullptr;
    const int32_t *cell_offsets = nullptr, *cell_members = nullptr;
    int64_t m = 0;
    std::vector<int32_t> cell_of = {};
};

struct Stats {
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0;
    // sort_length: keys ordered by depth (tile-splat pairs; 0 for wsr, whose tile lists are only binned;
    // tile-cell pairs for duplex); pairs: entries of the tile lists that the blend walks.
    int64_t visible = 0, sort_length = 0, pairs = 0;
    // duplex: visible cells, and tile-splat pairs of the splats' own rectangles outside their cell's rectangle
    // (pixels there miss the splat: the cell ellipsoid does not cover it on screen).
    int64_t cells_visible = 0, cell_misses = 0;
};

// Binning of splats, in parallel: each of up to BIN_THREADS threads counts the tiles of its static range of splats, a
// prefix sum over (tile, range) gives every range its slots in every tile, and each range writes its (depth bits,
// splat id) keys there. The ranges are in splat order, so each tile's list is in splat order as a sequential pass
// would leave it; then (when `sort`) each tile's list is sorted by depth; wsr keeps the splat order. The key buffer
// is sized between the two parallel passes (an allocation failure is a MemoryError, not an abort inside OpenMP).
constexpr int BIN_THREADS = 8;  // bounds the counts buffer (ranges x tiles) on many-core machines

void bin_splats(const std::vector<Splat2D>& splats, const std::vector<TileRect>& rects,
                const std::vector<uint8_t>& valid, int gx, bool sort, std::vector<int64_t>& tile_start,
                std::vector<uint64_t>& keys, Stats& st) {
    const int num_tiles = (int)tile_start.size() - 1;
    const int64_t n = (int64_t)splats.size();
    auto t0 = Clock::now();
    const int ranges = std::max(1, std::min(omp_get_max_threads(), BIN_THREADS));
    std::vector<int64_t> slots((size_t)ranges * num_tiles, 0);  // [range][tile]: counts, then write cursors
    int64_t visible = 0;
#pragma omp parallel for num_threads(ranges) schedule(static, 1) reduction(+ : visible)
    for (int k = 0; k < ranges; ++k) {
        int64_t* count = slots.data() + (size_t)k * num_tiles;
        for (int64_t i = n * k / ranges; i < n * (k + 1) / ranges; ++i) {
            if (!valid[i]) continue;
            ++visible;
            const TileRect& r = rects[i];
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) ++count[ty * gx + tx];
        }
    }
    int64_t total = 0;
    for (int t = 0; t < num_tiles; ++t) {
        tile_start[t] = total;
        for (int k = 0; k < ranges; ++k) {
            const int64_t c = slots[(size_t)k * num_tiles + t];
            slots[(size_t)k * num_tiles + t] = total;
            total += c;
        }
    }
    tile_start[num_tiles] = total;
    keys.resize(total);
#pragma omp parallel for num_threads(ranges) schedule(static, 1)
    for (int k = 0; k < ranges; ++k) {
        int64_t* cursor = slots.data() + (size_t)k * num_tiles;
        for (int64_t i = n * k / ranges; i < n * (k + 1) / ranges; ++i) {
            if (!valid[i]) continue;
            uint32_t depth_bits;
            std::memcpy(&depth_bits, &splats[i].depth, 4);  // depth > near > 0: bits sort as floats
            const uint64_t key = ((uint64_t)depth_bits << 32) | (uint32_t)i;
            const TileRect& r = rects[i];
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) keys[cursor[ty * gx + tx]++] = key;
        }
    }
    if (sort) {
#pragma omp parallel for schedule(dynamic, 4)
        for (int t = 0; t < num_tiles; ++t)
            std::sort(keys.begin() + tile_start[t], keys.begin() + tile_start[t + 1]);
        st.sort_length += total;
    }
    st.sort_ms += ms_since(t0);
    st.visible += visible;
    st.pairs += total;
}

// Duplex binning (KERNELS.md §8.3): each cell with at least one visible splat is projected as an ellipsoid; one
// depth sort of the (tile, cell depth, cell index) keys orders each tile's cells front to back; each tile's list
// is then its cells expanded to their visible splats, which follow a canonical order inside the cell
// (splat_less) so that the image does not depend on how the scene orders a cell's splats.
void bin_duplex(const SceneView& sc, const CameraParams& cam, const std::vector<Splat2D>& splats,
                const std::vector<TileRect>& rects, const std::vector<uint8_t>& valid, int gx, int gy,
                std::vector<int64_t>& tile_start, std::vector<uint64_t>& keys, Stats& st) {
    const int num_tiles = gx * gy;
    const int64_t m = sc.m;
    auto t0 = Clock::now();
    // visible members of each cell, canonically ordered; then the cell's screen proxy
    std::vector<int64_t> vis_start(m + 1, 0);
    for (int64_t c = 0; c < m; ++c) {
        int64_t cnt = 0;
        for (int32_t j = sc.cell_offsets[c]; j < sc.cell_offsets[c + 1]; ++j) cnt += valid[sc.cell_members[j]];
        vis_start[c + 1] = vis_start[c] + cnt;
    }
    std::vector<int32_t> vis(vis_start[m]);
    std::vector<Cell2D> cells(m);
    std::vector<TileRect> crects(m);
    std::vector<uint8_t> cvalid(m, 0);
#pragma omp parallel for schedule(static)
    for (int64_t c = 0; c < m; ++c) {
        int64_t o = vis_start[c];
        for (int32_t j = sc.cell_offsets[c]; j < sc.cell_offsets[c + 1]; ++j)
            if (valid[sc.cell_members[j]]) vis[o++] = sc.cell_members[j];
        if (o == vis_start[c]) continue;
        std::sort(vis.begin() + vis_start[c], vis.begin() + o,
                  [&](int32_t a, int32_t b) { return splat_less(splats[a], splats[b]); });
        CellIn in{sc.cell_means + 3 * c, sc.cell_scales + 3 * c, sc.cell_quats + 4 * c};
        cvalid[c] = preprocess_cell(in, cam, gx, gy, &cells[c], &crects[c]);
    }
    st.preprocess_ms += ms_since(t0);

    t0 = Clock::now();
    std::vector<int64_t> cell_tile_start(num_tiles + 1, 0);
    int64_t visible_cells = 0, misses = 0;
    for (int64_t c = 0; c < m; ++c) {
        if (!cvalid[c]) continue;
        ++visible_cells;
        const TileRect& r = crects[c];
        const int64_t members = vis_start[c + 1] - vis_start[c];
        for (int ty = r.y0; ty < r.y1; ++ty)
            for (int tx = r.x0; tx < r.x1; ++tx) {
                ++cell_tile_start[ty * gx + tx + 1];
                tile_start[ty * gx + tx + 1] += members;
            }
        for (int64_t j = vis_start[c]; j < vis_start[c + 1]; ++j) misses += tiles_outside(rects[vis[j]], r);
    }
    for (int t = 0; t < num_tiles; ++t) {
        cell_tile_start[t + 1] += cell_tile_start[t];
        tile_start[t + 1] += tile_start[t];
    }
    const int64_t cell_pairs = cell_tile_start[num_tiles];
    std::vector<uint64_t> ckeys(cell_pairs);
    {
        std::vector<int64_t> cursor(cell_tile_start.begin(), cell_tile_start.end() - 1);
        for (int64_t c = 0; c < m; ++c) {
            if (!cvalid[c]) continue;
            uint32_t depth_bits;
            std::memcpy(&depth_bits, &cells[c].depth, 4);
            const uint64_t key = ((uint64_t)depth_bits << 32) | (uint32_t)c;
            const TileRect& r = crects[c];
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) ckeys[cursor[ty * gx + tx]++] = key;
        }
    }
    keys.resize(tile_start[num_tiles]);
#pragma omp parallel for schedule(dynamic, 4)
    for (int t = 0; t < num_tiles; ++t) {
        std::sort(ckeys.begin() + cell_tile_start[t], ckeys.begin() + cell_tile_start[t + 1]);
        int64_t o = tile_start[t];
        for (int64_t k = cell_tile_start[t]; k < cell_tile_start[t + 1]; ++k) {
            const uint32_t c = (uint32_t)ckeys[k];
            for (int64_t j = vis_start[c]; j < vis_start[c + 1]; ++j) keys[o++] = (uint32_t)vis[j];
        }
    }
    st.sort_ms += ms_since(t0);
    int64_t visible = 0;  // splats that survive preprocess, as in the other modes
    for (uint8_t v : valid) visible += v;
    st.visible += visible;
    st.cells_visible += visible_cells;
    st.cell_misses += misses;
    st.sort_length += cell_pairs;
    st.pairs += tile_start[num_tiles];
}

// Box a splat's SplatBounds span (blend_tile skips a lane group whose box misses it, without evaluating the splat).
// scalar, mip, wsr, duplex: the pixel centres where the splat can pass its cut-off, the ellipse power >=
// log_min_alpha, i.e. d^T conic d <= r2 with r2 = -2 log_min_alpha, whose half-extents are sqrt(r2 Sigma_xx) and
// sqrt(r2 Sigma_yy) (Sigma = conic^-1), computed in double and widened for float rounding: the float power at a pixel
// is off by at most ~4 ulp of conic-weighted |d|^2, i.e. a relative 2.4e-7 (lambda_max / lambda_min) of r2 at the
// ellipse, so the box grows by 1e-6 kappa^2 + 1e-5 relative plus 0.01 px (the rounding of d = xy - pixel). duplex
// also has its radius circle. gaussian_blending: the window centres within radius + half perimeter, so the square of
// half side radius (the group box adds the half perimeters). analytic (alpha integrated over the pixel): no box.
std::atomic<bool> g_pixel_boxes{true};  // off only in tests, to show the boxes change no pixel

SplatBounds splat_bounds(const Splat2D& s, Mode mode) {
    constexpr float inf = std::numeric_limits<float>::infinity();
    if (mode == ANALYTIC || !g_pixel_boxes.load(std::memory_order_relaxed)) return {-inf, inf, -inf, inf};
    if (mode == GAUSSIAN_BLENDING) {
        const double r = (double)s.radius * (1.0 + 1e-6) + 0.01 + 1e-6 * (fabs(s.xy.x) + fabs(s.xy.y));
        return {(float)(s.xy.x - r), (float)(s.xy.x + r), (float)(s.xy.y - r), (float)(s.xy.y + r)};
    }
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

// Flush-to-zero and denormals-are-zero for the calling thread while in scope: one subnormal lane would slow a whole
// vector many times (exp of a very negative argument, products of tiny weights); results differ from IEEE only
// below 1.2e-38.
struct FlushDenormals {
#if defined(__SSE__) || defined(__x86_64__)
    unsigned saved = _mm_getcsr();
    FlushDenormals() { _mm_setcsr(saved | 0x8040u); }
    ~FlushDenormals() { _mm_setcsr(saved); }
#endif
};

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

// Every splat's SplatBounds in `mode`.
void splat_boxes(const std::vector<Splat2D>& splats, Mode mode, std::vector<SplatBounds>& boxes) {
    boxes.resize(splats.size());
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < (int64_t)splats.size(); ++i) boxes[i] = splat_bounds(splats[i], mode);
}

// Blend: each tile copies its splats (and their boxes) into contiguous per-thread buffers, then the selected SIMD
// path blends its pixels in lane groups.
void blend_tiles(const std::vector<Splat2D>& splats, const std::vector<int64_t>& tile_start,
                 const std::vector<uint64_t>& keys, const CameraParams& cam, Mode mode, const OitParams& oit,
                 const float bg[3], BlendTileFn blend_tile, std::vector<SplatBounds>& boxes, Image& img, Stats& st,
                 const Progress& progress, int N) {
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE;
    const int num_tiles = (int)tile_start.size() - 1;
    const std::vector<int> order = centre_out_order(gx, num_tiles / gx);
    auto t0 = Clock::now();
    splat_boxes(splats, mode, boxes);
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
            if (progress.cancelled()) continue;  // a cancelled frame skips its remaining tiles
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
            if (progress.partial) write_partial(img, N, job.x0, job.y0, job.x1, job.y1, progress.partial);
            progress.tile_done();
        }
    }
    st.blend_ms += ms_since(t0);
}

struct FrameBuffers {
    std::vector<Splat2D> splats;
    std::vector<TileRect> rects;
    std::vector<uint8_t> valid;
    std::vector<int64_t> tile_start;
    std::vector<uint64_t> keys;
    std::vector<SplatBounds> boxes;
};

// Per-frame buffers reused between frames (no allocation, no page faults in the frame loop once sizes settle): a
// render takes a set and gives it back; at most two sets are kept (two renders at once), a set much larger than a
// frame needs is dropped, and release_buffers() (the Python renderer calls it when its scene changes) frees them.
class BufferPool {
    std::mutex mutex_;
    std::vector<std::unique_ptr<FrameBuffers>> free_;

  public:
    std::unique_ptr<FrameBuffers> take() {
        std::lock_guard<std::mutex> lock(mutex_);
        if (free_.empty()) return std::make_unique<FrameBuffers>();
        std::unique_ptr<FrameBuffers> b = std::move(free_.back());
        free_.pop_back();
        return b;
    }
    void give(std::unique_ptr<FrameBuffers> b) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (free_.size() < 2) free_.push_back(std::move(b));
    }
    void clear() {
        std::lock_guard<std::mutex> lock(mutex_);
        free_.clear();
    }
};
BufferPool g_buffers;

// A set from the pool for the scope of one render, returned even when the render throws.
struct PooledBuffers {
    std::unique_ptr<FrameBuffers> buf = g_buffers.take();
    ~PooledBuffers() { g_buffers.give(std::move(buf)); }
};

// Test switch: keep a copy of the last frame's preprocess output (per splat: the valid flag, then the Splat2D and
// TileRect bytes when valid, zeros when culled), so tests can compare the SIMD paths' preprocess bit for bit.
std::atomic<bool> g_capture{false};
std::mutex g_capture_mutex;
std::vector<uint8_t> g_captured;

constexpr int64_t PREPROCESS_BLOCK = 256;  // splats per call of a path's preprocess (a multiple of 16)

// Preprocess and bin one image at the camera's resolution into `buf`: its splats and its tiles' lists (stops early
// once `progress` is cancelled).
void bin_frame(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
               const simd::Path& path, FrameBuffers& buf, Stats& st, const Progress& progress) {
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE;
    const int num_tiles = gx * gy;
    const int64_t n = sc.n;
    progress.start(num_tiles);

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
        if (progress.cancelled()) continue;  // a cancelled frame stops here too, not only between tiles
        path.preprocess(job, b * PREPROCESS_BLOCK, std::min(n, (b + 1) * PREPROCESS_BLOCK));
    }
    if (progress.cancelled()) return;
    if (g_capture.load(std::memory_order_relaxed)) {
        constexpr size_t rec = 1 + sizeof(Splat2D) + sizeof(TileRect);
        std::lock_guard<std::mutex> lock(g_capture_mutex);
        g_captured.assign((size_t)n * rec, 0);
        for (int64_t i = 0; i < n; ++i) {
            uint8_t* p = g_captured.data() + (size_t)i * rec;
            p[0] = valid[i];
            if (!valid[i]) continue;
            std::memcpy(p + 1, &splats[i], sizeof(Splat2D));
            std::memcpy(p + 1 + sizeof(Splat2D), &rects[i], sizeof(TileRect));
        }
    }
    st.preprocess_ms += ms_since(t0);

    std::vector<int64_t>& tile_start = buf.tile_start;
    std::vector<uint64_t>& keys = buf.keys;  // per tile list entry: splat id in the low 32 bits
    tile_start.assign(num_tiles + 1, 0);
    if (mode == DUPLEX) {
        bin_duplex(sc, cam, splats, rects, valid, gx, gy, tile_start, keys, st);
    } else {
        bin_splats(splats, rects, valid, gx, mode != WSR, tile_start, keys, st);
    }
    if (keys.capacity() > 4 * keys.size() + (1u << 20)) keys.shrink_to_fit();  // after a much larger frame
}

// Render one image at the camera's resolution, one sample per pixel.
void render_image(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
                  const float bg[3], const simd::Path& path, FrameBuffers& buf, Image& img, Stats& st,
                  const Progress& progress, int N = 1) {
    bin_frame(sc, cam, mode, oit, sh_deg, path, buf, st, progress);
    if (progress.cancelled()) return;
    blend_tiles(buf.splats, buf.tile_start, buf.keys, cam, mode, oit, bg, path.blend_tile, buf.boxes, img, st,
                progress, N);
}

// The pixel trace (trace.h) of output pixel (x, y) at N x N samples; `cam` is the sub-sample grid's camera.
PixelTrace trace_frame_pixel(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int sh_deg, const float bg[3], const simd::Path& path, FrameBuffers& buf, int x, int y,
                             int N) {
    Stats st;
    bin_frame(sc, cam, mode, oit, sh_deg, path, buf, st, Progress{});
    splat_boxes(buf.splats, mode, buf.boxes);
    FrameLists lists = {buf.splats.data(), buf.boxes.data(), buf.tile_start.data(), buf.keys.data(), cam.width,
                        cam.height, mode, oit, {bg[0], bg[1], bg[2]}};
    FlushDenormals ftz;
    return trace_pixel(lists, x, y, N);
}

nb::dict render(FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter_3d,
                FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height, float near_plane,
                int projection, int mode, int supersample, int sh_degree, FArr background, bool want_window,
                int threads, std::optional<FArr> weight_sh, std::optional<FArr> cell_means,
                std::optional<FArr> cell_scales, std::optional<FArr> cell_quats, std::optional<IArr> cell_offsets,
                std::optional<IArr> cell_members, float sigma, float weight_background, float et_grade,
                bool depth_correct, std::optional<LArr> control, std::optional<PArr> partial,
                std::optional<std::array<int, 2>> trace) {
    const int64_t n = check_scene("render", means, scales, quats, opacities, sh, filter_3d);
    if (control && control->shape(0) != 3) throw std::invalid_argument("render: control must hold 3 int64");
    if (partial && (partial->shape(0) != (size_t)height || partial->shape(1) != (size_t)width ||
                    partial->shape(2) != 3))
        throw std::invalid_argument("render: partial must be float32 (height, width, 3)");
    const Progress progress{control ? control->data() : nullptr, partial ? partial->data() : nullptr};
    const RenderArgs args = parse_render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane, projection,
                                              mode, supersample, background, sigma, weight_background, et_grade,
                                              depth_correct);
    const int k = (int)sh.shape(1);
    const int sh_deg = std::max(0, std::min(sh_degree, sh_degree_for_coeffs(k)));
    SceneView sc{means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                 filter_3d ? filter_3d->data() : nullptr, n, k};
    if (weight_sh) {
        sc.weight_k = check_weight_sh("render", *weight_sh, n);
        sc.weight_sh = weight_sh->data();
    }
    if (mode == DUPLEX) {
        if (!(cell_means && cell_scales && cell_quats && cell_offsets && cell_members))
            throw std::invalid_argument("render: duplex needs cell_means, cell_scales, cell_quats, cell_offsets, "
                                        "cell_members");
        const int64_t m = check_cell_arrays("render", *cell_means, *cell_scales, *cell_quats, *cell_offsets);
        sc.cell_of = partition_cell_of("render", cell_offsets->data(), cell_members->data(), m,
                                       (int64_t)cell_members->size(), n);
        sc.cell_means = cell_means->data();
        sc.cell_scales = cell_scales->data();
        sc.cell_quats = cell_quats->data();
        sc.cell_offsets = cell_offsets->data();
        sc.cell_members = cell_members->data();
        sc.m = m;
    }
    const OitParams oit = args.oit;
    const int N = supersample;
    const CameraParams& cam = args.cam;
    const float* bg = args.bg;
    const bool window = want_window && mode == GAUSSIAN_BLENDING;

    if (trace && !((*trace)[0] >= 0 && (*trace)[0] < width && (*trace)[1] >= 0 && (*trace)[1] < height))
        fail("render", "trace pixel outside the image");
    Image out;
    Stats st;
    PixelTrace traced;
    const simd::Path& path = simd::current();  // the one this frame runs and reports, whatever set_simd does meanwhile
    {
        nb::gil_scoped_release release;
        PooledBuffers pooled;
        const int prev_threads = omp_get_max_threads();
        if (threads > 0) omp_set_num_threads(threads);
        if (!trace) out.resize(width, height, window);
        if (trace) {
            traced = trace_frame_pixel(sc, cam, (Mode)mode, oit, sh_deg, bg, path, *pooled.buf, (*trace)[0],
                                       (*trace)[1], N);
        } else if (N == 1) {
            render_image(sc, cam, (Mode)mode, oit, sh_deg, bg, path, *pooled.buf, out, st, progress);
        } else {
            Image hi;
            hi.resize(width * N, height * N, window);
            render_image(sc, cam, (Mode)mode, oit, sh_deg, bg, path, *pooled.buf, hi, st, progress, N);
            auto t0 = Clock::now();
            if (!progress.cancelled()) box_downsample(hi, N, out);
            st.blend_ms += ms_since(t0);
        }
        if (threads > 0) omp_set_num_threads(prev_threads);
    }
    if (trace) return trace_dict(std::move(traced));
    nb::dict d = result_dict(out, st, (size_t)height, (size_t)width);
    d["simd"] = path.name;
    d["cancelled"] = progress.cancelled();
    return d;
}

// Exp evaluations per second on one core through a SIMD path's exp (the benchmark's reference rate).
double exp_rate(const std::string& path, int64_t n) {
    for (const simd::Path* p : simd::supported()) {
        if (path != p->name) continue;
        nb::gil_scoped_release release;
        FlushDenormals ftz;
        auto t0 = Clock::now();
        volatile float sink = p->exp_sum(n);
        (void)sink;
        return (double)n / (ms_since(t0) * 1e-3);
    }
    simd::select(path);  // throws the error naming the available paths
    return 0.0;
}

}  // namespace

NB_MODULE(_native, m) {
    m.doc() = "gbviewer CPU renderer (C++17, OpenMP; blend vectorised with Google Highway, chosen at run time)";
    simd::init_from_env();
    m.def("simd", [] { return std::string(simd::current().name); }, "The SIMD path renders use.");
    m.def("simd_paths", [] {
        std::vector<std::string> names;
        for (const simd::Path* p : simd::supported()) names.push_back(p->name);
        return names;
    }, "SIMD paths this CPU and build can run, best last.");
    m.def("set_simd", [](const std::string& name) { simd::select(name); }, nb::arg("name"),
          "Use this SIMD path for later renders (scalar, avx2, avx512).");
    m.def("release_buffers", [] { g_buffers.clear(); }, "Free the per-frame buffers kept between renders.");
    m.def("set_pixel_boxes", [](bool on) { g_pixel_boxes.store(on); }, nb::arg("on"),
          "Test switch: skip lane groups outside a splat's pixel box (default) or evaluate every list entry.");
    m.def("set_capture_preprocess", [](bool on) { g_capture.store(on); }, nb::arg("on"),
          "Test switch: keep the next renders' preprocess output for captured_preprocess().");
    m.def("captured_preprocess", [] {
        std::lock_guard<std::mutex> lock(g_capture_mutex);
        return nb::bytes(reinterpret_cast<const char*>(g_captured.data()), g_captured.size());
    }, "The last captured frame's preprocess: per splat the valid byte, then its Splat2D and TileRect (zeros when culled).");
    m.def("exp_rate", &exp_rate, nb::arg("path"), nb::arg("n"),
          "Exp evaluations per second on one core through the path's vector exp.");
    m.def("render", &render, nb::arg("means"), nb::arg("scales"), nb::arg("quats"), nb::arg("opacities"),
          nb::arg("sh"), nb::arg("filter_3d").none(), nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"),
          nb::arg("cx"), nb::arg("cy"), nb::arg("width"), nb::arg("height"), nb::arg("near_plane"),
          nb::arg("projection"), nb::arg("mode"), nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"),
          nb::arg("want_window"), nb::arg("threads"), nb::arg("weight_sh").none() = nb::none(),
          nb::arg("cell_means").none() = nb::none(), nb::arg("cell_scales").none() = nb::none(),
          nb::arg("cell_quats").none() = nb::none(), nb::arg("cell_offsets").none() = nb::none(),
          nb::arg("cell_members").none() = nb::none(), nb::arg("sigma") = 10.0f,
          nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false,
          nb::arg("control").none() = nb::none(), nb::arg("partial").none() = nb::none(),
          nb::arg("trace").none() = nb::none(),
          "Render a frame; with trace = (x, y), instead the pixel trace of that output pixel (trace.h).");
}
