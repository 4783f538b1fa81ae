// CUDA renderer: plain C++ interface (no CUDA types) so that the nanobind module is compiled by the host
// compiler and only the .cu files go through nvcc.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "gbv/args.h"
#include "gbv/common.h"

namespace gbv::cuda {

struct RenderResult {
    std::vector<float> rgb, alpha, window;
    std::vector<int32_t> evals;
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0;
    int64_t visible = 0, sort_length = 0, pairs = 0;
    int64_t cells_visible = 0, cell_misses = 0;  // duplex, as the CPU module defines them (0 otherwise)
    int64_t evaluations = 0;  // render_to_gl_texture: the sum of the evaluation counts (render: see `evals`)
    bool stage_reused = false;  // the per-camera stage was an earlier frame's (same scene, camera, SH degree, reach)
    double stage_ms = 0;  // building the stage in this frame (0 when reused; part of preprocess_ms)
};

// A CUDA error after which the device is unusable in this process (a fault in a kernel, a watchdog timeout, the
// device lost: CUDA's "sticky" errors, which every later call on the context returns). The renderer refuses every
// later call with the same reason, and no new renderer is made on that device.
struct DeviceFailed : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// (CUDA's name of error `code`, whether it counts as DeviceFailed without asking the device). No device needed.
std::pair<std::string, bool> error_info(int code);

// The element count a device buffer of `capacity` elements allocates for a request of n: n itself the first time
// (no head room: a render that fits must not fail for lack of it), then 1.5x the old capacity, at least n, so a
// growing scene reallocates O(log) times. (A failed 1.5x allocation is retried at n.)
inline size_t grown_capacity(size_t capacity, size_t n) {
    if (n <= capacity) return capacity;
    return capacity == 0 ? std::max<size_t>(n, 1) : std::max(n, capacity + capacity / 2);
}

// (usable, reason): false with the CUDA runtime's explanation when there is no device or driver, or when the
// default device failed in this process; true with the name of the device a Renderer() uses by default.
std::pair<bool, std::string> availability();

// The device Renderer(-1) uses on this thread: the runtime's current device (0 unless the thread selected another);
// -1 without a usable runtime.
int default_device();

// (free, total) bytes of `device`'s memory (its context made current for the call, as a renderer's calls do).
std::pair<size_t, size_t> memory_info(int device);

// The CUDA devices that drive the OpenGL context current on this thread (empty when none is current, it runs on
// another vendor's driver or the driver cannot tell).
std::vector<int> gl_devices();

struct State;  // device buffers and per-frame state (state.h, nvcc only)

// One renderer owns its device buffers. Every method is serialised by a mutex of the renderer, so threads may share
// one (the Python binding releases the GIL before it takes the mutex); each call makes the renderer's device current
// on the calling thread for its duration and restores the thread's previous device after.
class Renderer {
  public:
    // device < 0: default_device(). Checks that this device exists, has not failed and is sm_75 or newer.
    explicit Renderer(int device = -1);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    int device() const { return device_; }

    // Copy the scene to the device (activated parameters, as gbviewer.Scene); k >= 1 SH coefficients; n may be 0.
    // Forgets the previous scene, view weights and cells first, so after a failure (out of device memory) the
    // renderer has no scene until an upload succeeds. Every successful upload starts a new scene generation.
    void upload(const float* means, const float* scales, const float* quats, const float* opacities, const float* sh,
                const float* filter_3d, int64_t n, int k);

    // The uploaded scene's splat count and generation ({0, 0} before the first successful upload), read together.
    struct SceneInfo {
        int64_t n = 0;
        uint64_t generation = 0;
    };
    SceneInfo scene() const;

    // The sort-free view-weight SH (n, weight_k) of the scene `generation` (what the caller checked the array
    // against): throws when another scene was uploaded since, so arrays checked for one scene never reach another.
    void upload_weights(const float* weight_sh, int64_t n, int weight_k, uint64_t generation);

    // Duplex cells of the scene `generation` (as upload_weights): cell c holds members[offsets[c] .. offsets[c+1]);
    // cell_of[i] per splat (n entries). The caller checks that this is a partition: the kernels index with it
    // unchecked.
    void upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                      const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members,
                      uint64_t generation);

    // A level-of-detail hierarchy's m interior nodes of the scene `generation` (as upload_weights), k SH coefficients
    // and a 3D filter as the scene's: rows n .. n + m - 1 after the scene's splats (the scene's rows stay on the
    // device). Forgets the previous nodes and cut first.
    void upload_lod(const float* means, const float* scales, const float* quats, const float* opacities,
                    const float* sh, const float* filter_3d, int64_t m, int k, uint64_t generation);

    // A cut through the uploaded hierarchy that renders with `cut` draw in place, of the scene `generation`: frame
    // splat i is row rows[i] (each within the scene's and the nodes' rows: checked here) with its opacity times
    // weights[i].
    void upload_cut(const int32_t* rows, const float* weights, int64_t count, uint64_t generation);

    // Render at a.cam's resolution (supersample x the output size per axis) and box-average back; `cut`: the
    // uploaded cut (upload_cut) in place of the scene's splats (not duplex, whose cells are the scene's).
    RenderResult render(const RenderArgs& a, bool cut = false);

    // Render and write RGBA (rgb, alpha) into an OpenGL texture (GL_RGBA32F, the output size, row 0 the image top)
    // through CUDA-GL interop, without a round trip through host memory; returns the stats (rgb/alpha/evals empty,
    // `evaluations` summed on the device). The texture's GL context (or one sharing it) must be current on this
    // thread. The texture stays registered with CUDA (per texture name) until release_gl_texture; a registration
    // whose array no longer has the texture's size is made again. Throws when the current GL context runs on
    // another CUDA device than this renderer's. The CUDA writes have finished and the texture is unmapped when it
    // returns (the caller flushes GL before another context samples it).
    RenderResult render_to_gl_texture(unsigned int texture, const RenderArgs& a, bool cut = false);

    // Drop the CUDA registration of a texture (no-op when it has none); its GL context must be current.
    void release_gl_texture(unsigned int texture);

    // Forget the scene and free every device buffer (the texture registrations stay): the next upload and frame
    // allocate again. A scene is uploaded again before the next render.
    void release_buffers();

  private:
    int device_;
    std::unique_ptr<State> state_;
};

}  // namespace gbv::cuda
