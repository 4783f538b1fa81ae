// The Renderer class (renderer.h): the device checks of its construction; per call the mutex, the device guard and
// the DeviceFailed latch; uploads; copying results back. The frame steps are in binning.cu, duplex.cu, blend.cu,
// interop.cu.
#include <algorithm>
#include <string>

#include "state.h"

namespace gbv::cuda {
using namespace detail;
namespace {

// A call on the renderer: holds its mutex and its device (restored after), refuses a renderer whose device failed
// and latches a DeviceFailed thrown during the call (later calls throw it again).
template <class F>
auto call(State& s, F&& body) {
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.failed.empty()) throw DeviceFailed(s.failed);
    try {
        DeviceGuard guard(s.device);
        return body();
    } catch (const DeviceFailed& e) {
        s.failed = e.what();
        throw;
    }
}

// count elements from host memory into buf (at least one element allocated).
template <class T>
void put(DeviceBuffer<T>& buf, const T* src, size_t count) {
    buf.ensure(std::max<size_t>(count, 1));
    if (count) CUDA_CHECK(cudaMemcpy(buf.ptr, src, count * sizeof(T), cudaMemcpyHostToDevice));
}

// count elements from host memory into buf after its first `keep`, which stay (copied on the device into a new
// buffer where it grows).
template <class T>
void put_after(DeviceBuffer<T>& buf, size_t keep, const T* src, size_t count) {
    if (keep + count > buf.capacity) {
        DeviceBuffer<T> grown;
        grown.ensure(std::max<size_t>(keep + count, 1));
        if (keep) CUDA_CHECK(cudaMemcpy(grown.ptr, buf.ptr, keep * sizeof(T), cudaMemcpyDeviceToDevice));
        std::swap(buf.ptr, grown.ptr);  // the old allocation goes with `grown`
        std::swap(buf.capacity, grown.capacity);
    }
    if (count) CUDA_CHECK(cudaMemcpy(buf.ptr + keep, src, count * sizeof(T), cudaMemcpyHostToDevice));
}

// count elements from device memory into a host vector.
template <class T>
void get(std::vector<T>& out, const T* src, size_t count) {
    out.resize(count);
    CUDA_CHECK(cudaMemcpy(out.data(), src, count * sizeof(T), cudaMemcpyDeviceToHost));
}

}  // namespace

Renderer::Renderer(int device) {
    if (device < 0) device = default_device();
    int count = 0;
    const cudaError_t e = cudaGetDeviceCount(&count);
    if (e != cudaSuccess) {
        cudaGetLastError();
        throw std::runtime_error(std::string("no usable CUDA device: ") + cudaGetErrorString(e));
    }
    if (device < 0 || device >= count)
        throw std::runtime_error("CUDA device " + std::to_string(device) + " does not exist (" + std::to_string(count) +
                                 " found)");
    const auto [ok, why] = usable(device);  // the requested device's architecture, not the current one's
    if (!ok) throw std::runtime_error(why);
    device_ = device;
    DeviceGuard guard(device);
    state_ = std::make_unique<State>(device);
}

Renderer::~Renderer() {
    try {
        DeviceGuard guard(device_);  // frees and texture unregistrations on the renderer's device
        state_.reset();
    } catch (const std::exception&) {  // the device cannot be made current (it failed): its frees fail harmlessly
        state_.reset();
    }
    cudaGetLastError();
}

Renderer::SceneInfo Renderer::scene() const {
    std::lock_guard<std::mutex> lock(state_->mutex);
    return state_->has_scene ? SceneInfo{state_->n, state_->generation} : SceneInfo{};
}

void Renderer::upload(const float* means, const float* scales, const float* quats, const float* opacities,
                      const float* sh, const float* filter_3d, int64_t n, int k) {
    State& s = *state_;
    call(s, [&] {
        s.forget_scene();
        if (n >= (1ll << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 - 1 splats");
        if (k < 1) throw std::runtime_error("CUDA renderer: SH arrays need K >= 1 coefficients");
        put(s.means, means, n * 3);
        put(s.scales, scales, n * 3);
        put(s.quats, quats, n * 4);
        put(s.opacities, opacities, n);
        put(s.sh, sh, (size_t)n * k * 3);
        if (filter_3d) put(s.filter_3d, filter_3d, n);
        s.has_filter = filter_3d != nullptr;
        s.n = n;
        s.k = k;
        s.has_scene = true;
        ++s.generation;
    });
}

void Renderer::upload_weights(const float* weight_sh, int64_t n, int weight_k, uint64_t generation) {
    State& s = *state_;
    call(s, [&] {
        host::replace_derived(
            s.has_scene, s.generation, generation, "view weights", [&] { s.weight_k = 0; },
            [&] {
                if (n != s.n) throw std::runtime_error("CUDA renderer: view weights for another scene size");
                put(s.weight_sh, weight_sh, (size_t)n * weight_k);
                s.weight_k = weight_k;
            });
    });
}

void Renderer::upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                            const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members,
                            uint64_t generation) {
    State& s = *state_;
    call(s, [&] {
        host::replace_derived(
            s.has_scene, s.generation, generation, "cells",
            [&] {
                s.has_cells = false;
                s.m = s.num_members = 0;
            },
            [&] {
                if (num_cells >= (1ll << 31) || num_members >= (1ll << 31))
                    throw std::runtime_error("CUDA renderer: more than 2^31 - 1 cells or cell members");
                put(s.cmeans, means, num_cells * 3);
                put(s.cscales, scales, num_cells * 3);
                put(s.cquats, quats, num_cells * 4);
                put(s.coffsets, offsets, num_cells + 1);
                put(s.cmembers, members, num_members);
                put(s.cell_of, cell_of, s.n);
                s.m = num_cells;
                s.num_members = num_members;
                s.has_cells = true;
            });
    });
}

void Renderer::upload_lod(const float* means, const float* scales, const float* quats, const float* opacities,
                          const float* sh, const float* filter_3d, int64_t m, int k, uint64_t generation) {
    State& s = *state_;
    call(s, [&] {
        host::replace_derived(
            s.has_scene, s.generation, generation, "level-of-detail nodes",
            [&] {
                s.has_lod = s.has_cut = false;
                s.lod_m = s.cut_count = 0;
            },
            [&] {
                if (k != s.k || (filter_3d != nullptr) != s.has_filter)
                    throw std::runtime_error(
                        "CUDA renderer: level-of-detail nodes need the scene's SH size and 3D "
                        "filter");
                if (s.n + m >= (1ll << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 - 1 rows");
                const size_t n = (size_t)s.n;
                put_after(s.means, n * 3, means, m * 3);
                put_after(s.scales, n * 3, scales, m * 3);
                put_after(s.quats, n * 4, quats, m * 4);
                put_after(s.opacities, n, opacities, m);
                put_after(s.sh, n * k * 3, sh, (size_t)m * k * 3);
                if (filter_3d) put_after(s.filter_3d, n, filter_3d, m);
                s.lod_m = m;
                s.has_lod = true;
            });
    });
}

void Renderer::upload_cut(const int32_t* rows, const float* weights, int64_t count, uint64_t generation) {
    State& s = *state_;
    call(s, [&] {
        host::check_generation(s.has_scene, s.generation, generation, "level-of-detail cut");
        if (!s.has_lod) throw std::runtime_error("CUDA renderer: upload_lod before upload_cut");
        const int64_t total = s.n + s.lod_m;
        for (int64_t i = 0; i < count; ++i)
            if (rows[i] < 0 || rows[i] >= total)
                throw std::invalid_argument("upload_cut: rows must index the scene's splats and the hierarchy's nodes");
        s.has_cut = false;
        s.cut_count = 0;
        put(s.cut_rows, rows, count);
        put(s.cut_weights, weights, count);
        s.cut_count = count;
        s.has_cut = true;
        ++s.cut_generation;
    });
}

RenderResult Renderer::render(const RenderArgs& a, bool cut) {
    State& s = *state_;
    return call(s, [&] {
        RenderResult res;
        s.run(a, res, cut);
        const bool ss = a.supersample > 1;
        const size_t px = (size_t)a.width * a.height;
        get(res.rgb, ss ? s.o_rgb.ptr : s.rgb.ptr, px * 3);
        get(res.alpha, ss ? s.o_alpha.ptr : s.alpha.ptr, px);
        get(res.evals, ss ? s.o_evals.ptr : s.evals.ptr, px);
        if (a.want_window && a.mode == GAUSSIAN_BLENDING) get(res.window, ss ? s.o_window.ptr : s.window.ptr, px * 2);
        return res;
    });
}

RenderResult Renderer::render_to_gl_texture(unsigned int texture, const RenderArgs& a, bool cut) {
    State& s = *state_;
    return call(s, [&] {
        const std::vector<int> gl = gl_devices();
        if (gl.empty())
            throw std::runtime_error(
                "render_to_gl_texture: the OpenGL context current on this thread does not run "
                "on a CUDA device (or none is current)");
        if (std::find(gl.begin(), gl.end(), s.device) == gl.end())
            throw std::runtime_error("render_to_gl_texture: the current OpenGL context runs on CUDA device " +
                                     std::to_string(gl[0]) + ", this renderer on device " + std::to_string(s.device) +
                                     "; create the renderer on the GL device");
        RenderArgs plain = a;
        plain.want_window = false;
        RenderResult res;
        s.run(plain, res, cut);
        const bool ss = a.supersample > 1;
        const int64_t px = (int64_t)a.width * a.height;
        s.pack_rgba(px, ss ? s.o_rgb.ptr : s.rgb.ptr, ss ? s.o_alpha.ptr : s.alpha.ptr);
        res.evaluations = s.sum_evals(ss ? s.o_evals.ptr : s.evals.ptr, px);
        s.copy_to_texture(texture, a.width, a.height);
        return res;
    });
}

void Renderer::release_buffers() {
    State& s = *state_;
    call(s, [&] {
        s.forget_scene();
        s.release_buffers();
    });
}

// Not refused after a DeviceFailed: the registration is then forgotten without a call into the broken context.
void Renderer::release_gl_texture(unsigned int texture) {
    State& s = *state_;
    {
        std::lock_guard<std::mutex> lock(s.mutex);
        if (!s.failed.empty()) {
            s.textures.erase(texture);
            return;
        }
    }
    call(s, [&] { s.release_texture(texture); });
}

}  // namespace gbv::cuda
