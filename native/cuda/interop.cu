// CUDA-GL interop: the texture registrations of a renderer (per GL texture name, kept between frames: registering
// costs more than the copy) and the copy of a frame into a texture. GL names are reused after deletion and are
// unique per share group only, so a registration is checked at every use: one that no longer maps, or whose array
// has another size or format than the frame, is made again once. (The Python wrapper also drops a registration
// whose name now belongs to another texture object: gbviewer/render/cuda_textures.py.)
#include <algorithm>

#include "state.h"

namespace gbv::cuda {
using namespace detail;
namespace {

// Whether the mapped array is RGBA32F of w x h; e: the first error.
bool array_fits(cudaGraphicsResource_t resource, int w, int h, cudaArray_t* array, cudaError_t* e) {
    *e = cudaGraphicsSubResourceGetMappedArray(array, resource, 0, 0);
    if (*e != cudaSuccess) return false;
    cudaChannelFormatDesc desc;
    cudaExtent extent;
    unsigned int flags;
    *e = cudaArrayGetInfo(&desc, &extent, &flags, *array);
    return *e == cudaSuccess && extent.width == (size_t)w && extent.height == (size_t)h && desc.x == 32 &&
           desc.y == 32 && desc.z == 32 && desc.w == 32 && desc.f == cudaChannelFormatKindFloat;
}

}  // namespace

std::vector<int> gl_devices() {
    unsigned int count = 0;
    int devices[16];
    if (cudaGLGetDevices(&count, devices, 16, cudaGLDeviceListAll) != cudaSuccess) {
        cudaGetLastError();
        return {};
    }
    return std::vector<int>(devices, devices + std::min(count, 16u));
}

// Registrations are dropped only while a GL context on a CUDA device is current (the worker releases its display
// textures with its context current); without one (at interpreter exit) unregistering is undefined, so they are
// left to the CUDA context's teardown.
State::~State() {
    if (textures.empty() || gl_devices().empty()) return;
    for (auto& [name, resource] : textures) cudaGraphicsUnregisterResource(resource);
    cudaGetLastError();
}

void State::release_texture(unsigned int texture) {
    const auto it = textures.find(texture);
    if (it == textures.end()) return;
    const cudaError_t e = cudaGraphicsUnregisterResource(it->second);
    textures.erase(it);
    check(e, "cudaGraphicsUnregisterResource (GL texture)");
}

void State::copy_to_texture(unsigned int texture, int w, int h) {
    cudaError_t e = cudaSuccess;
    for (int attempt = 0; attempt < 2; ++attempt) {
        auto it = textures.find(texture);
        if (it == textures.end()) {
            cudaGraphicsResource_t resource;
            CUDA_CHECK(
                cudaGraphicsGLRegisterImage(&resource, texture, GL_TEXTURE_2D, cudaGraphicsRegisterFlagsWriteDiscard));
            it = textures.emplace(texture, resource).first;
        }
        cudaGraphicsResource_t resource = it->second;
        e = cudaGraphicsMapResources(1, &resource);
        if (e == cudaSuccess) {
            cudaArray_t array;
            const bool fits = array_fits(resource, w, h, &array, &e);
            if (fits) {
                e = cudaMemcpy2DToArray(array, 0, 0, rgba.ptr, w * sizeof(float4), w * sizeof(float4), h,
                                        cudaMemcpyDeviceToDevice);
                if (e == cudaSuccess) e = cudaStreamSynchronize(0);
            }
            const cudaError_t unmap = cudaGraphicsUnmapResources(1, &resource);
            if (fits) {
                check(e == cudaSuccess ? unmap : e, "render_to_gl_texture (copy into the GL texture)");
                return;
            }
        }
        // stale (the name now holds another texture, or it was respecified): register again once
        cudaGetLastError();
        cudaGraphicsUnregisterResource(resource);
        cudaGetLastError();
        textures.erase(it);
    }
    if (e != cudaSuccess) check(e, "cudaGraphicsMapResources (GL texture)");
    throw std::runtime_error("render_to_gl_texture: texture " + std::to_string(texture) +
                             " is not an RGBA32F texture of the render's size " + std::to_string(w) + "x" +
                             std::to_string(h));
}

}  // namespace gbv::cuda
