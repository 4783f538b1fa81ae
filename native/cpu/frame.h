// The CPU frame driver behind Renderer (renderer.cpp): the per-camera stage and each mode's finish of it (parallel
// over blocks of splats, in vector lanes), per-tile binning and depth sort (binning.cpp), blending (parallel over the
// tiles of every frame of a call together, dynamic schedule; frame.cpp). The math is in include/gbv/*.h, shared with
// CUDA.
#pragma once

#include "omp_shim.h"
#if defined(__SSE__) || defined(__x86_64__)
#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#endif
#endif

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <vector>

#include "plane.h"
#include "renderer.h"
#include "simd.h"

namespace gbv::cpu {

using Clock = std::chrono::steady_clock;
inline double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Flush-to-zero and denormals-are-zero for the calling thread while in scope: one subnormal lane would slow a whole
// vector many times (exp of a very negative argument, products of tiny weights); results differ from IEEE only
// below 1.2e-38.
struct FlushDenormals {
#if defined(__SSE__) || defined(__x86_64__)
    unsigned saved = _mm_getcsr();
    FlushDenormals() { _mm_setcsr(saved | 0x8040u); }
    ~FlushDenormals() { _mm_setcsr(saved); }
#elif defined(__aarch64__)
    uint64_t saved = fpcr();
    FlushDenormals() { set_fpcr(saved | (1u << 24)); }  // FPCR.FZ: subnormal inputs and results are zero
    ~FlushDenormals() { set_fpcr(saved); }
    static uint64_t fpcr() {
        uint64_t v;
        __asm__ __volatile__("mrs %0, fpcr" : "=r"(v));
        return v;
    }
    static void set_fpcr(uint64_t v) { __asm__ __volatile__("msr fpcr, %0" : : "r"(v)); }
#endif
};

// The uploaded scene as the driver reads it.
struct SceneView {
    const float *means = nullptr, *scales = nullptr, *quats = nullptr, *opacities = nullptr, *sh = nullptr,
                *filter_3d = nullptr;
    int64_t n = 0;
    int k = 1;  // SH coefficients per channel
    const float* weight_sh = nullptr;  // (n, weight_k) sort-free view-weight SH, or null
    int weight_k = 0;
    // Duplex cells: cell c holds the splats members[offsets[c] .. offsets[c+1]); cell_of[i] is splat i's cell.
    const float *cell_means = nullptr, *cell_scales = nullptr, *cell_quats = nullptr;
    const int32_t *cell_offsets = nullptr, *cell_members = nullptr;
    int64_t m = 0;
    std::vector<int32_t> cell_of = {};
    // The scene's splat hierarchy (lod.h Tree's arrays), for level-of-detail frames: its interior nodes' Gaussians
    // (the scene's layouts), the cut's inputs; levels[0..num_levels). num_levels 0: none uploaded.
    struct Hierarchy {
        const float *means = nullptr, *scales = nullptr, *quats = nullptr, *opacities = nullptr, *sh = nullptr,
                    *filter_3d = nullptr, *radius = nullptr, *size = nullptr;
        const int64_t* levels = nullptr;
        const int32_t* order = nullptr;
        int num_levels = 0;
    } tree;
};

// What a stage depends on (built by stage_key, renderer.cpp, the one place that fills it): the uploaded scene (its
// upload generation: upload, upload_weights, upload_cells and upload_lod each start a new one), every byte of the
// camera (a supersampled frame's camera is its own), the SH degree, the reach of its on-screen cull
// (stage_on_screen: the largest diagonal the frame's 2D filter adds, at least 3DGS's +0.3, so every built-in mode and
// preset shares one), the level-of-detail cut it draws (off: every splat) and the presets' stage rules (stage_rules).
struct StageKey {
    uint64_t scene = 0;
    CameraParams cam = {};
    int sh_deg = 0;
    float reach = DILATION_3DGS;
    LodArgs lod = {};
    int rules = 0;  // stage_rules: the presets' base-colour clamp and radial depth
    bool operator==(const StageKey& o) const {
        return scene == o.scene && sh_deg == o.sh_deg && reach == o.reach && lod == o.lod && rules == o.rules &&
               std::memcmp(&cam, &o.cam, sizeof cam) == 0;
    }
};

// The per-camera stage (preprocess_range.h) every mode's finish reads, kept by the renderer while its key holds.
struct Stage {
    StageKey key;
    bool ready = false;  // built for key (false while building and after a cancelled build)
    // A level-of-detail stage's cut (StageJob::rows, weights): its splat i is that row of the scene or hierarchy.
    // Empty when it draws every splat of the scene (no LOD, or a cut that is the scene's leaves; splats.size() says
    // which, an empty cut drawing none).
    Plane<int32_t> rows;
    Plane<float> weights;
    std::vector<StageSplat> splats;
    std::vector<uint8_t> valid;  // in front of the near plane and on screen in some mode
    Plane<uint32_t> depth;  // StageJob::depth: a valid splat's depth bits, else NO_DEPTH
    // One depth order of the stage's valid splats (depth_order's keys), computed by the first frame that bins in
    // depth order and shared by every later one: each bins in it, skipping the splats its finish culls (a superset's
    // order gives the same tile lists). Not ready after build_stage or a cancelled sort.
    std::vector<uint64_t> order, order_scratch;
    bool order_ready = false;
    size_t bytes() const {
        return splats.capacity() * sizeof(StageSplat) + valid.capacity() + depth.capacity() * sizeof(uint32_t) +
               rows.capacity() * sizeof(int32_t) + weights.capacity() * sizeof(float) +
               (order.capacity() + order_scratch.capacity()) * sizeof(uint64_t);
    }
};

// A splat's tile rectangle at its place in the binning order (bin_splats).
struct RankedRect {
    uint16_t x0, y0, x1, y1;
};

// A frame's buffers, kept by the renderer between frames (no allocation, no page faults once sizes settle).
struct FrameBuffers {
    std::vector<Splat2D> splats;
    std::vector<TileRect> rects;  // empty (0, 0, 0, 0) where not valid: the binning reads no valid[]
    std::vector<uint8_t> valid;
    std::vector<int64_t> tile_start;
    std::vector<uint32_t> ids;  // per tile list entry: its splat (4 bytes: half the traffic of a depth key)
    std::vector<SplatBounds> boxes;
    std::vector<RankedRect> ranked;  // bin_splats' scratch
    std::vector<DepthPlane> planes;  // stochastic_popfree: per splat (others: empty)
    std::vector<RaySplat> rays;  // eval3d, stopthepop: each splat's ray data (finish_rays)
};

// A running call's cancel state and progress (Control) for its frames: the caller's flag or a report that asked to
// stop; the tiles blended so far per frame. Relaxed atomics: only counts and flags. Cancelled once, cancelled for
// good: a flag that the caller clears again while the frames stop (to reuse it) cannot resume a stage that stopped
// half-way.
class FrameRun {
  public:
    FrameRun(const Control& c, int frames) : c_(c), done_(frames), total_(frames, 0), last_(Clock::now()) {
        for (std::atomic<int64_t>& d : done_) d.store(0, std::memory_order_relaxed);
    }
    bool cancelled() const {
        if (stop_.load(std::memory_order_relaxed) || seen_.load(std::memory_order_relaxed)) return true;
        if (!c_.cancel || !__atomic_load_n(c_.cancel, __ATOMIC_RELAXED)) return false;
        seen_.store(true, std::memory_order_relaxed);
        return true;
    }
    bool stopped() const { return stop_.load(std::memory_order_relaxed); }
    float* partial(int frame) const { return (size_t)frame < c_.partial.size() ? c_.partial[frame] : nullptr; }
    void start(int frame, int64_t tiles) { total_[frame] = tiles; }
    void tile_done(int frame) { done_[frame].fetch_add(1, std::memory_order_relaxed); }
    // Called by every worker; reports on the calling thread only (OpenMP's master), at most every report_ms.
    void poll() {
        if (!c_.report || omp_get_thread_num() != 0 || cancelled()) return;
        const Clock::time_point now = Clock::now();
        if (std::chrono::duration<double, std::milli>(now - last_).count() < c_.report_ms) return;
        last_ = now;
        report();
    }
    // Every frame's count.
    void report() {
        for (int f = 0; c_.report && f < (int)total_.size() && !stopped(); ++f)
            if (!c_.report(f, done_[f].load(std::memory_order_relaxed), total_[f]))
                stop_.store(true, std::memory_order_relaxed);
    }

  private:
    const Control& c_;
    std::atomic<bool> stop_{false};
    mutable std::atomic<bool> seen_{false};  // the caller's flag was seen set
    std::vector<std::atomic<int64_t>> done_;
    std::vector<int64_t> total_;
    Clock::time_point last_;
};

// A thread's cancel check for loops of uneven steps: reads run.cancelled() once per CANCEL_WORK units of work
// (entries read or written), a fraction of a millisecond, so that the check costs nothing in the loop.
constexpr int64_t CANCEL_WORK = 1 << 15;
class CancelPoll {
  public:
    explicit CancelPoll(const FrameRun& run) : run_(run) {}
    bool operator()(int64_t work) {
        if ((left_ -= work) > 0) return false;
        left_ = CANCEL_WORK;
        return run_.cancelled();
    }

  private:
    const FrameRun& run_;
    int64_t left_ = CANCEL_WORK;
};

// order.cpp: the depth keys (depth bits, id) of the splats whose depth[i] is not NO_DEPTH, ascending, in `order`
// (resized to their count); `scratch` is the radix sort's second buffer. Parallel, checks run.cancelled(): a
// cancelled call leaves `order` unspecified (the caller checks run.cancelled() before using it).
void depth_order(const Plane<uint32_t>& depth, std::vector<uint64_t>& order, std::vector<uint64_t>& scratch,
                 FrameRun& run);

// binning.cpp: each tile's list of splat ids in the order of `order` (count depth keys, e.g. a depth_order; entries
// whose splat is not valid, its rect empty, are skipped, so the order of a superset serves), or in splat order when
// `order` is null (wsr); tile_start (num_tiles + 1 entries) gets each tile's first entry. duplex: the tiles' cells front to back,
// each expanded to its visible splats in canonical order. Both stop early once cancelled (tile_start and ids then
// unspecified).
void bin_splats(const std::vector<TileRect>& rects, const uint64_t* order, int64_t count, int gx,
                std::vector<int64_t>& tile_start, std::vector<uint32_t>& ids, std::vector<RankedRect>& ranked,
                Stats& st, FrameRun& run);
void bin_duplex(const SceneView& sc, const CameraParams& cam, const std::vector<Splat2D>& splats,
                const std::vector<TileRect>& rects, const std::vector<uint8_t>& valid, int gx, int gy,
                std::vector<int64_t>& tile_start, std::vector<uint32_t>& ids, Stats& st, FrameRun& run);

// rays.cpp: the per-pixel sorted modes' finish after (stopthepop) or instead of (eval3d) the SIMD path's: every
// splat's ray data (gbv/ray3d.h) into buf.rays; eval3d also sets splats, rects and valid from the stage: the splat
// as the stage has it (no 2D filter), the tiles its 3D footprint (ray_footprint) touches. stopthepop drops a valid
// splat whose ray data is degenerate.
void finish_rays(const SceneView& sc, const Stage& stage, Mode mode, FrameBuffers& buf, FrameRun& run);
// rays.cpp: stopthepop:K's stage 1 (gbv/resort.h): the tile list of `count` entries (and their boxes, rays and, when
// not null, splat ids) of the tile whose first pixel is (tx0, ty0) in the order of tile_depth_key, stable.
void tile_depth_order(const CameraParams& cam, int tx0, int ty0, int64_t count, Splat2D* list, SplatBounds* bounds,
                      RaySplat* rays, uint32_t* ids);

// frame.cpp: the stage of `key` into `stage` (every splat, or the level-of-detail cut's; stops early once cancelled,
// leaving it not ready).
void build_stage(const SceneView& sc, const StageKey& key, const simd::Path& path, Stage& stage, Stats& st,
                 FrameRun& run);
// The rectangle of the camera's image (at its resolution: supersampled) that a frame renders: [x0, x1) x [y0, y1),
// x0 and y0 multiples of TILE, so that its tiles are tiles of the whole image's grid.
struct TileRegion {
    int x0, y0, x1, y1;
    int gx() const { return (x1 - x0 + TILE - 1) / TILE; }
    int gy() const { return (y1 - y0 + TILE - 1) / TILE; }
    static TileRegion whole(const CameraParams& cam) { return {0, 0, cam.width, cam.height}; }
};

// The mode's finish of a ready stage and the binning of the tiles of `reg` (of the image at the camera's
// resolution) into `buf`, in the stage's depth order (sorted here when not ready yet); stops early once cancelled.
// Each tile's list is the whole image's list of that tile.
void bin_frame(const SceneView& sc, Stage& stage, Mode mode, const OitParams& oit, const simd::Path& path,
               FrameBuffers& buf, Stats& st, FrameRun& run, const TileRegion& reg);

// One frame of a call's joint blend: its binned buffers, how to blend them, and the image (at the stage camera's
// resolution; N: supersampling factor, for the partial frame).
struct BlendFrame {
    FrameBuffers* buf;  // its boxes are computed here
    const CameraParams* cam;
    Mode mode;
    OitParams oit;
    int queue;  // stopthepop's K
    const float* bg;
    Image* img;
    int N;
    Stats* st;
    uint32_t frame_key;  // stochastic: stochastic_frame_key(seed, frame)
    TileRegion reg;  // what of the camera's image `img` holds (bin_frame's region)
    bool fast;  // gaussian_blending's fast precision
};
// Blend every frame's tiles in one parallel loop, interleaved (each frame's tiles centre out, the frames' i-th tiles
// together, in proportion to their tile counts); each frame's blend_ms is the loop's time.
void blend_frames(const std::vector<BlendFrame>& frames, BlendTileFn blend_tile, FrameRun& run);
// The pixel trace of output pixel (x, y) at N x N samples from a ready stage (the sub-sample grid's camera).
PixelTrace trace_frame_pixel(const SceneView& sc, Stage& stage, Mode mode, const OitParams& oit, int queue,
                             uint32_t frame_key, bool fast, const float bg[3], const simd::Path& path,
                             FrameBuffers& buf, int x, int y, int N);

}  // namespace gbv::cpu
