// Device and host memory owned by objects (nvcc only): a renderer whose construction or frame fails part way leaks
// none of it.
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "device.h"

namespace gbv::cuda::detail {

// A device allocation that only grows (grown_capacity: the request itself first, then by 1.5x) and is reused
// between frames. Out of memory throws std::runtime_error (the device stays usable).
template <typename T>
struct DeviceBuffer {
    T* ptr = nullptr;
    size_t capacity = 0;
    void ensure(size_t n) {
        if (n <= capacity) return;
        const size_t grown = grown_capacity(capacity, n);
        release();
        cudaError_t e = cudaMalloc(&ptr, grown * sizeof(T));
        size_t count = grown;
        if (e == cudaErrorMemoryAllocation && grown > n) {  // the head room does not fit: the request alone may
            cudaGetLastError();
            count = n;
            e = cudaMalloc(&ptr, count * sizeof(T));
        }
        if (e != cudaSuccess) {
            ptr = nullptr;
            if (e == cudaErrorMemoryAllocation) {
                cudaGetLastError();
                throw std::runtime_error("CUDA out of device memory: could not allocate " +
                                         std::to_string((count * sizeof(T)) >> 20) + " MiB");
            }
            check(e, "cudaMalloc");
        }
        capacity = count;
    }
    void release() {
        if (ptr) cudaFree(ptr);
        ptr = nullptr;
        capacity = 0;
    }
    DeviceBuffer() = default;
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    ~DeviceBuffer() { release(); }
};

// A CUDA event.
struct Event {
    cudaEvent_t e = nullptr;
    Event() { CUDA_CHECK(cudaEventCreate(&e)); }
    Event(const Event&) = delete;
    Event& operator=(const Event&) = delete;
    ~Event() {
        if (e) cudaEventDestroy(e);
    }
};

// Page-locked host words that device totals are copied into (several copies, one wait).
struct HostTotals {
    static constexpr int WORDS = 8;
    unsigned long long* p = nullptr;
    HostTotals() { CUDA_CHECK(cudaMallocHost(&p, WORDS * sizeof(unsigned long long))); }
    HostTotals(const HostTotals&) = delete;
    HostTotals& operator=(const HostTotals&) = delete;
    ~HostTotals() {
        if (p) cudaFreeHost(p);
    }
};

}  // namespace gbv::cuda::detail
