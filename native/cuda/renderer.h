// CUDA renderer: plain C++ interface (no CUDA types) so that the nanobind module is compiled by the host
// compiler and only renderer.cu goes through nvcc.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gbv/common.h"

namespace gbv::cuda {

struct RenderResult {
    std::vector<float> rgb, alpha, window;
    std::vector<int32_t> evals;
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0;
    int64_t visible = 0, sort_length = 0, pairs = 0;
    int64_t cells_visible = 0, cell_misses = 0;  // duplex, as the CPU module defines them (0 otherwise)
    int64_t evaluations = 0;  // render_to_gl_texture: the sum of the evaluation counts (render: see `evals`)
};

// (usable, reason): false with the CUDA runtime's explanation when there is no device or driver; true with the
// name of the device a Renderer() uses by default.
std::pair<bool, std::string> availability();

// The CUDA devices that drive the OpenGL context current on this thread (empty when none is current, it runs on
// another vendor's driver or the driver cannot tell).
std::vector<int> gl_devices();

// One renderer owns its device buffers. Every method is serialised by a mutex of the renderer, so threads may share
// one (the Python binding releases the GIL while it uploads and renders); each call makes the renderer's device
// current on the calling thread.
class Renderer {
public:
    // device < 0: the runtime's current device (0 unless the thread selected another).
    explicit Renderer(int device = -1);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    int device() const;

    // Copy the scene to the device (activated parameters, as gbviewer.Scene); k = SH coefficients; n may be 0.
    // Forgets the previous scene, view weights and cells first, so after a failure (out of device memory) the
    // renderer has no scene until an upload succeeds.
    void upload(const float* means, const float* scales, const float* quats, const float* opacities, const float* sh,
                const float* filter_3d, int64_t n, int k);

    // Splats of the uploaded scene (0 before the first successful upload).
    int64_t num_splats() const;

    // The sort-free view-weight SH of the uploaded scene (n, weight_k), for wsr and duplex.
    void upload_weights(const float* weight_sh, int64_t n, int weight_k);

    // Duplex cells of the uploaded scene: cell c holds members[offsets[c] .. offsets[c+1]); cell_of[i] per splat
    // (num_splats() entries). The caller checks that this is a partition: the kernels index with it unchecked.
    void upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                      const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members);

    // Render at cam's resolution (supersample x the output size per axis) and box-average back.
    RenderResult render(const CameraParams& cam, Mode mode, int supersample, int sh_degree, const float bg[3],
                        bool want_window, const OitParams& oit);

    // Render and write RGBA (rgb, alpha) into an OpenGL texture (GL_RGBA32F, the output size, row 0 the image top)
    // through CUDA-GL interop, without a round trip through host memory; returns the stats (rgb/alpha/evals empty,
    // `evaluations` summed on the device). The texture's GL context (or one sharing it) must be current on this
    // thread. The texture stays registered with CUDA (per texture name) until release_gl_texture: call that before
    // deleting it, since GL reuses the names of deleted textures. Throws when the current GL context runs on
    // another CUDA device than this renderer's. The copy has finished when it returns.
    RenderResult render_to_gl_texture(unsigned int texture, const CameraParams& cam, Mode mode, int supersample,
                                      int sh_degree, const float bg[3], const OitParams& oit);

    // Drop the CUDA registration of a texture (no-op when it has none); its GL context must be current.
    void release_gl_texture(unsigned int texture);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace gbv::cuda
