// Error classification, the process's failed devices, device guards, availability (device.h, renderer.h).
#include <map>
#include <mutex>

#include "device.h"

namespace gbv::cuda {
namespace detail {
namespace {

std::mutex failed_mutex;
std::map<int, std::string> failed_devices;  // device -> the first fatal error's message

}  // namespace

bool is_fatal(cudaError_t e) {
    switch (e) {
        case cudaErrorIllegalAddress:
        case cudaErrorLaunchFailure:
        case cudaErrorLaunchTimeout:
        case cudaErrorHardwareStackError:
        case cudaErrorIllegalInstruction:
        case cudaErrorMisalignedAddress:
        case cudaErrorInvalidAddressSpace:
        case cudaErrorInvalidPc:
        case cudaErrorAssert:
        case cudaErrorECCUncorrectable:
        case cudaErrorNvlinkUncorrectable:
        case cudaErrorDevicesUnavailable:
        case cudaErrorNoDevice:
        case cudaErrorContextIsDestroyed:
        case cudaErrorCudartUnloading:
            return true;
        default:
            return false;
    }
}

std::string failure(int device) {
    std::lock_guard<std::mutex> lock(failed_mutex);
    const auto it = failed_devices.find(device);
    return it == failed_devices.end() ? std::string() : it->second;
}

void check(cudaError_t e, const char* what) {
    if (e == cudaSuccess) return;
    std::string msg = std::string("CUDA error in ") + what + ": " + cudaGetErrorString(e);
    cudaGetLastError();  // clears a non-sticky error (a sticky one stays)
    bool fatal = is_fatal(e);
    if (!fatal && e != cudaErrorMemoryAllocation) {
        const cudaError_t probe = cudaDeviceSynchronize();  // a sticky error shows here too
        if (probe != cudaSuccess && probe != cudaErrorMemoryAllocation) {
            fatal = true;
            msg += std::string(" (then ") + cudaGetErrorString(probe) + ")";
        }
    }
    if (!fatal) throw std::runtime_error(msg);
    int device = -1;
    cudaGetDevice(&device);
    msg = "CUDA device " + std::to_string(device) + " failed: " + msg;
    {
        std::lock_guard<std::mutex> lock(failed_mutex);
        failed_devices.emplace(device, msg);  // the first reason stays
    }
    throw DeviceFailed(msg);
}

void launched(const char* kernel) {
    check(cudaGetLastError(), kernel);
#ifndef NDEBUG
    check(cudaDeviceSynchronize(), kernel);
#endif
}

std::pair<bool, std::string> usable(int device) {
    const std::string failed = failure(device);
    if (!failed.empty()) return {false, failed};
    cudaDeviceProp prop;
    const cudaError_t e = cudaGetDeviceProperties(&prop, device);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, "CUDA device " + std::to_string(device) + ": " + cudaGetErrorString(e)};
    }
    if (prop.major < 7 || (prop.major == 7 && prop.minor < 5))
        return {false, std::string(prop.name) + " is older than sm_75, the oldest architecture built"};
    return {true, prop.name};
}

DeviceGuard::DeviceGuard(int device) : device_(device) {
    CUDA_CHECK(cudaGetDevice(&previous_));
    if (previous_ != device_) CUDA_CHECK(cudaSetDevice(device_));
}

DeviceGuard::~DeviceGuard() {
    if (previous_ >= 0 && previous_ != device_) cudaSetDevice(previous_);
}

}  // namespace detail

std::pair<std::string, bool> error_info(int code) {
    const cudaError_t e = (cudaError_t)code;
    return {cudaGetErrorName(e), detail::is_fatal(e)};
}

int default_device() {
    int device = -1;
    if (cudaGetDevice(&device) != cudaSuccess) {
        cudaGetLastError();
        return -1;
    }
    return device;
}

std::pair<bool, std::string> availability() {
    int count = 0;
    const cudaError_t e = cudaGetDeviceCount(&count);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, std::string("no usable CUDA device: ") + cudaGetErrorString(e)};
    }
    if (count == 0) return {false, "no CUDA device found"};
    const int device = default_device();
    if (device < 0) return {false, "no usable CUDA device: the runtime has no current device"};
    return detail::usable(device);
}

}  // namespace gbv::cuda
