// CPU renderer: the same shape as the CUDA one (native/cuda/renderer.h), plain C++ (the nanobind module is
// bindings.cpp). Upload a scene once, then render frames of it with a RenderArgs (gbv/args.h) each; trace one pixel.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

#include "gbv/args.h"
#include "image.h"
#include "trace.h"

namespace gbv::cpu {

// What a frame measured. preprocess_ms includes stage_ms, the time spent building the per-camera stage in this
// frame (0 when stage_reused: the stage of an earlier frame, or of an earlier frame of the same call, was used).
// render_many's frames blend in one loop: each frame's blend_ms is that loop's time. sort_length: keys ordered by depth (tile-splat pairs; 0 for wsr, whose tile lists are only
// binned; tile-cell pairs for duplex); pairs: entries of the tile lists that the blend walks. duplex: visible cells,
// and tile-splat pairs of the splats' own rectangles outside their cell's rectangle (pixels there miss the splat).
struct Stats {
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0, stage_ms = 0;
    double order_ms = 0;  // the stage's depth order sorted in this frame (included in sort_ms; 0 when reused)
    bool stage_reused = false;
    bool order_reused = false;  // binned in a depth order an earlier frame of the stage sorted (not wsr, duplex)
    int64_t visible = 0, sort_length = 0, pairs = 0;
    int64_t cells_visible = 0, cell_misses = 0;
    int64_t lod_drawn = -1;  // a level-of-detail frame: the splats and interior nodes of its cut
};

// How one render runs and what it tells its caller; every field optional.
struct Control {
    // The caller's cancel flag (nonzero: stop), read by every worker thread between blocks of splats and tiles.
    const int64_t* cancel = nullptr;
    // Per frame (may be shorter: none for the rest), float32 (height, width, 3) output pixels: each finished tile is
    // written there at once (a refining frame).
    std::vector<float*> partial;
    // report(frame, tiles done, tiles in the frame) for every frame of the call, called on the thread that called
    // render (OpenMP's master thread) between blocks and tiles, at most every report_ms, and once at the end of a
    // call that was not cancelled. Returning false stops the call as a cancel does (RenderResult::stopped).
    std::function<bool(int, int64_t, int64_t)> report;
    double report_ms = 5.0;
    int threads = 0;  // OpenMP threads, 0 = the runtime's default
};

struct RenderResult {
    Image image;  // output size: rgb, alpha, evals, window (gaussian_blending with want_window)
    Stats stats;
    const char* simd;  // the SIMD path the frame ran
    bool cancelled = false;  // stopped by the cancel flag or by report: the image is incomplete
    bool stopped = false;  // stopped because report returned false
};

// One renderer owns its per-frame buffers and the per-camera stages of its last call (StageKey, frame.h): renders of
// the same camera, scene and SH degree reuse the stage, whatever their mode and other settings. Every method is serialised by a mutex of the renderer (threads may share
// one); the scene stays the caller's: upload references its arrays (no copy) and keeps `owner` until the next upload
// or the renderer's end, so the arrays must stay unchanged while uploaded.
class Renderer {
  public:
    Renderer();
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    // The scene (activated parameters, as gbviewer.Scene); k = SH coefficients per channel; n may be 0. Forgets the
    // previous scene, view weights and cells (not the per-frame buffers: a trained model's views, uploaded per frame,
    // reuse them; a frame of a much smaller scene drops them).
    void upload(const float* means, const float* scales, const float* quats, const float* opacities, const float* sh,
                const float* filter_3d, int64_t n, int k, std::shared_ptr<const void> owner);

    // Splats of the uploaded scene (0 before the first upload).
    int64_t num_splats() const;
    // Its SH coefficients per channel and whether it has a 3D filter.
    std::pair<int, bool> scene_layout() const;

    // The sort-free view-weight SH of the uploaded scene (n, weight_k), for wsr and duplex.
    void upload_weights(const float* weight_sh, int64_t n, int weight_k, std::shared_ptr<const void> owner);

    // Duplex cells of the uploaded scene: cell c holds members[offsets[c] .. offsets[c+1]); cell_of[i] per splat
    // (num_splats() entries, copied). The caller checks that this is a partition: the driver indexes with it.
    void upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                      const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members,
                      std::shared_ptr<const void> owner);

    // The uploaded scene's splat hierarchy (lod.h Tree's arrays, referenced like the scene's: interior nodes'
    // Gaussians, radius and size, levels[0..num_levels), order): frames with RenderArgs::lod draw its cut in place.
    // The caller checks that it is the scene's (gbviewer.lod.Hierarchy.check); upload forgets it.
    // Throws std::invalid_argument unless its leaves, SH size k and 3D filter are the uploaded scene's.
    void upload_lod(const float* means, const float* scales, const float* quats, const float* opacities,
                    const float* sh, int k, const float* filter_3d, const float* radius, const float* size,
                    const int64_t* levels, int num_levels, const int32_t* order, std::shared_ptr<const void> owner);

    // Render at args.cam's resolution (supersample x the output size per axis) and box-average back. Throws
    // std::invalid_argument for duplex without cells.
    RenderResult render(const RenderArgs& args, const Control& control = {});

    // Render several frames in one call: the stage once per distinct StageKey, each frame's finish and binning, then
    // one parallel loop over every frame's tiles interleaved (frame 0's first tile, frame 1's first, ...); control's
    // cancel and report cover all of them. The results are render()'s of each frame, bit for bit.
    std::vector<RenderResult> render_many(const std::vector<RenderArgs>& frames, const Control& control = {});

    // The trace (trace.h) of output pixel (x, y) of the frame `args` renders; (x, y) inside the output image.
    PixelTrace trace(const RenderArgs& args, int x, int y);

    // Free the per-frame buffers and stages kept for the next frame (gbviewer's CpuRenderer does when its scene
    // changes), and their size in bytes.
    void release_buffers();
    size_t buffer_bytes() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace gbv::cpu
