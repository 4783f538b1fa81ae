// The CPU frame driver behind Renderer (renderer.cpp): preprocess (parallel over blocks of splats, in vector lanes),
// per-tile binning and depth sort (binning.cpp), blending (parallel over tiles, dynamic schedule; frame.cpp). The
// math is in include/gbv/*.h, shared with CUDA.
#pragma once

#include <omp.h>
#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#endif

#include <atomic>
#include <chrono>
#include <cstdint>
#include <vector>

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
};

// A frame's buffers, kept by the renderer between frames (no allocation, no page faults once sizes settle).
struct FrameBuffers {
    std::vector<Splat2D> splats;
    std::vector<TileRect> rects;
    std::vector<uint8_t> valid;
    std::vector<int64_t> tile_start;
    std::vector<uint64_t> keys;  // per tile list entry: splat id in the low 32 bits
    std::vector<SplatBounds> boxes;
};

// A running frame's cancel state and progress (Control): the caller's flag or a report that asked to stop; the
// tiles blended so far. Relaxed atomics: only counts and flags.
class FrameRun {
public:
    explicit FrameRun(const Control& c) : c_(c), last_(Clock::now()) {}
    bool cancelled() const {
        return stop_.load(std::memory_order_relaxed) || (c_.cancel && __atomic_load_n(c_.cancel, __ATOMIC_RELAXED));
    }
    bool stopped() const { return stop_.load(std::memory_order_relaxed); }
    float* partial() const { return c_.partial; }
    void start(int64_t tiles) { total_ = tiles; }
    void tile_done() { done_.fetch_add(1, std::memory_order_relaxed); }
    // Called by every worker; reports on the calling thread only (OpenMP's master), at most every report_ms.
    void poll() {
        if (!c_.report || omp_get_thread_num() != 0 || cancelled()) return;
        const Clock::time_point now = Clock::now();
        if (std::chrono::duration<double, std::milli>(now - last_).count() < c_.report_ms) return;
        last_ = now;
        report();
    }
    void report() {
        if (c_.report && !c_.report(done_.load(std::memory_order_relaxed), total_))
            stop_.store(true, std::memory_order_relaxed);
    }

private:
    const Control& c_;
    std::atomic<bool> stop_{false};
    std::atomic<int64_t> done_{0};
    int64_t total_ = 0;
    Clock::time_point last_;
};

// binning.cpp: each tile's list of (depth bits, splat id) keys, sorted by depth unless `sort` is false (wsr); duplex:
// the tiles' cells front to back, each expanded to its visible splats in canonical order.
void bin_splats(const std::vector<Splat2D>& splats, const std::vector<TileRect>& rects,
                const std::vector<uint8_t>& valid, int gx, bool sort, std::vector<int64_t>& tile_start,
                std::vector<uint64_t>& keys, Stats& st);
void bin_duplex(const SceneView& sc, const CameraParams& cam, const std::vector<Splat2D>& splats,
                const std::vector<TileRect>& rects, const std::vector<uint8_t>& valid, int gx, int gy,
                std::vector<int64_t>& tile_start, std::vector<uint64_t>& keys, Stats& st);

// frame.cpp: preprocess and bin one image at the camera's resolution into `buf` (stops early once cancelled).
void bin_frame(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
               const simd::Path& path, FrameBuffers& buf, Stats& st, FrameRun& run);
// Render one image at the camera's resolution into `img` (N: supersampling factor, for the partial frame).
void render_image(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit, int sh_deg,
                  const float bg[3], const simd::Path& path, FrameBuffers& buf, Image& img, Stats& st, FrameRun& run,
                  int N);
// The pixel trace of output pixel (x, y) at N x N samples; `cam` is the sub-sample grid's camera.
PixelTrace trace_frame_pixel(const SceneView& sc, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int sh_deg, const float bg[3], const simd::Path& path, FrameBuffers& buf, int x, int y,
                             int N);

}  // namespace gbv::cpu
