// CUDA renderer: plain C++ interface (no CUDA types) so that the nanobind module is compiled by the host
// compiler and only renderer.cu goes through nvcc.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "gbv/common.h"

namespace gbv::cuda {

struct RenderResult {
    std::vector<float> rgb, alpha, window;
    std::vector<int32_t> evals;
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0;
    int64_t visible = 0, sort_length = 0;
};

// (usable, reason): false with the CUDA runtime's explanation when there is no device or driver.
std::pair<bool, std::string> availability();

class Renderer {
public:
    Renderer();
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    // Copy the scene to the device once (activated parameters, as gbviewer.Scene); k = SH coefficients.
    void upload(const float* means, const float* scales, const float* quats, const float* opacities, const float* sh,
                const float* filter_3d, int64_t n, int k);

    // Render at cam's resolution times `supersample` per axis and box-average back; cam is at output size.
    RenderResult render(const CameraParams& cam, Mode mode, int supersample, int sh_degree, const float bg[3],
                        bool want_window);

    // Render and copy the RGBA result into an OpenGL texture (GL_RGBA32F, cam-sized) through CUDA-GL interop,
    // without a round trip through host memory.
    void render_to_gl_texture(unsigned int texture, const CameraParams& cam, Mode mode, int supersample,
                              int sh_degree, const float bg[3]);

private:
    struct Impl;
    Impl* impl_;
};

}  // namespace gbv::cuda
