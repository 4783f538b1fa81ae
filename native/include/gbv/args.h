// The per-frame arguments of a render call, as both native renderers (CPU and CUDA) take them: one struct, checked
// by the bindings (native/bindings/nb_common.h: parse_render_args) before it reaches a renderer.
#pragma once

#include "gbv/camera.h"
#include "gbv/common.h"

namespace gbv {

struct RenderArgs {
    CameraParams cam;   // at supersample x the output size: supersampling renders there and box-averages
    Mode mode;
    int supersample;    // N, 1..8
    int width, height;  // output size
    float bg[3];
    OitParams oit;      // wsr / duplex globals
    int sh_degree = 3;  // SH degree cap, 0..3
    bool want_window = false;  // Gaussian Blending's final window size per pixel as a debug plane
};

}  // namespace gbv
