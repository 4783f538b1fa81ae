// The pixel trace: one output pixel (each of its N x N sub-samples) blended by the scalar path's own tile code
// (blend_tile<Lanes1>, the per-lane steps of gbv/blend.h that the vector paths are tested equal to) on a one-pixel
// rectangle of its tile's list, with a recorder as the tracer (gbv/trace.h): one record per list entry.
#pragma once

#include <vector>

#include "blend_tile.h"
#include "image.h"

namespace gbv {

// What a frame's binning leaves for its blend (frame.cpp): the splats and their boxes by splat id, the tile lists
// (tile t: the splats ids[tile_start[t] .. tile_start[t + 1])), at the frame's size (the
// sub-sample grid when supersampling).
struct FrameLists {
    const Splat2D* splats;
    const SplatBounds* boxes;
    const int64_t* tile_start;
    const uint32_t* ids;
    const RaySplat* rays;  // eval3d, stopthepop: per splat (else null)
    int width, height;
    Mode mode;
    OitParams oit;
    int queue;
    float bg[3];
    uint32_t frame_key;  // stochastic: stochastic_frame_key(seed, frame)
    const DepthPlane* planes;  // stochastic_popfree: per splat, or null
    bool fast;  // gaussian_blending's fast precision
    const CameraParams* cam;  // stopthepop:K: the camera of the tile stage's key (tile_depth_order)
};

// One list entry at one sub-sample: the splat as the blend saw it and what it did there. alpha and weight are 0
// where the kernel computed none or added nothing; T, the window and the duplex cell state are the pixel's after the
// entry (unchanged from before it when skipped).
struct TraceStep {
    int32_t sample, index, skip, flags;  // flags: TRACE_FALLBACK, TRACE_STOPPED
    float alpha, weight, T_before, T_after;
    float window[4];  // gaussian_blending: centre x, y and size w, h after the entry
    float T_cell;  // duplex
    int32_t cell;
    Splat2D splat;
};
constexpr int32_t TRACE_FALLBACK = 1;  // gaussian_blending's scalar fallback (window too narrow or too wide)
constexpr int32_t TRACE_STOPPED = 2;  // the pixel stopped at this entry

struct PixelTrace {
    std::vector<TraceStep> steps;  // sample by sample (row-major sub-samples), each in list order
    std::vector<float> totals;  // per sample: the sum its weights were divided by (wsr, duplex; 1 otherwise)
    Image samples;  // N x N: each sub-sample as the render writes it
    Image pixel;  // 1 x 1: their box average, as the render writes the pixel
};

// Trace output pixel (x, y) of a frame whose lists are at N x its size. Run with flush-to-zero like the render.
PixelTrace trace_pixel(const FrameLists& frame, int x, int y, int N);

}  // namespace gbv
