// The per-frame arguments of a render call, as both native renderers (CPU and CUDA) take them: one struct, checked
// by the bindings (native/bindings/nb_common.h: parse_render_args) before it reaches a renderer.
#pragma once

#include "gbv/camera.h"
#include "gbv/common.h"

namespace gbv {

// A level-of-detail frame (the CPU renderer, native/cpu/lod.h): draw the cut at tau pixels through the uploaded
// hierarchy, for the eye (perspective) and the larger focal length of the output camera. tau < 0: every splat.
struct LodArgs {
    double tau = -1.0, band = 1.0;
    float eye[3] = {0, 0, 0};
    double focal = 0.0;
    bool orthographic = false;
    bool on() const { return tau >= 0.0; }
    bool operator==(const LodArgs& o) const {
        return tau == o.tau && band == o.band && eye[0] == o.eye[0] && eye[1] == o.eye[1] && eye[2] == o.eye[2] &&
               focal == o.focal && orthographic == o.orthographic;
    }
};

struct RenderArgs {
    CameraParams cam;  // at supersample x the output size: supersampling renders there and box-averages
    Mode mode;
    int supersample;  // N, 1..8
    int width, height;  // output size
    float bg[3];
    OitParams oit;  // wsr / duplex globals
    int sh_degree = 3;  // SH degree cap, 0..3
    bool want_window = false;  // Gaussian Blending's final window size per pixel as a debug plane
    int queue = STOPTHEPOP_QUEUE;  // stopthepop: the per-pixel queue length K (0: unbounded, the exact sort)
    LodArgs lod;  // CPU only: the CUDA renderer draws a cut gathered into a scene of its own
    uint32_t seed = 0, frame = 0;  // stochastic: the hash's seed and frame index (stochastic.h)
    // CPU only: the part of the output image rendered, [rx, rx + rw) x [ry, ry + rh) output pixels (rw = 0: all of
    // it), every pixel as the whole image's (the camera, its culling and its tile grid stay the whole image's);
    // rx x supersample and ry x supersample are multiples of TILE.
    int rx = 0, ry = 0, rw = 0, rh = 0;
    bool fast = false;  // gaussian_blending at the fast precision (blend.h: blend_gaussian's Fast)
};

}  // namespace gbv
