// Error classification, the process's failed devices, device guards, availability (device.h, renderer.h).
#include <cuda.h>  // the driver API's types only: its one call is looked up at run time (no libcuda link)

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

namespace {

// Whether a CUDA context is current on this thread (cuCtxGetCurrent, looked up through the runtime so that the
// module loads where no driver is installed). Where it cannot be asked, a context is assumed (the guard then
// restores as a thread that had chosen a device).
bool has_context() {
    using GetCurrent = CUresult (*)(CUcontext*);
    static const GetCurrent get_current = [] {
        void* fn = nullptr;
        cudaDriverEntryPointQueryResult found = cudaDriverEntryPointSymbolNotFound;
#if CUDART_VERSION >= 12050
        const cudaError_t e =
            cudaGetDriverEntryPointByVersion("cuCtxGetCurrent", &fn, 12000, cudaEnableDefault, &found);
#else
        const cudaError_t e = cudaGetDriverEntryPoint("cuCtxGetCurrent", &fn, cudaEnableDefault, &found);
#endif
        if (e != cudaSuccess) cudaGetLastError();
        return e == cudaSuccess && found == cudaDriverEntryPointSuccess ? reinterpret_cast<GetCurrent>(fn) : nullptr;
    }();
    CUcontext ctx = nullptr;
    return get_current == nullptr || (get_current(&ctx) == CUDA_SUCCESS && ctx != nullptr);
}

// The CUDA runtime as host_logic.h's templates call it.
struct Runtime {
    static std::string error_string(int e) { return cudaGetErrorString((cudaError_t)e); }
    static void clear_error() { cudaGetLastError(); }
    static bool is_fatal(int e) { return detail::is_fatal((cudaError_t)e); }
    static bool out_of_memory(int e) { return e == cudaErrorMemoryAllocation; }
    static int synchronize() { return cudaDeviceSynchronize(); }
    static int current_device() {
        int device = -1;
        if (cudaGetDevice(&device) != cudaSuccess) {
            cudaGetLastError();
            return -1;
        }
        return device;
    }
    [[noreturn]] static void fail(int device, const std::string& msg) {
        {
            std::lock_guard<std::mutex> lock(failed_mutex);
            failed_devices.emplace(device, msg);  // the first reason stays
        }
        throw DeviceFailed(msg);
    }
    static bool has_context() { return detail::has_context(); }
    static int set_device(int device) { return cudaSetDevice(device); }
    static void check(int e, const char* what, int device) { detail::check((cudaError_t)e, what, device); }
};

}  // namespace

void check(cudaError_t e, const char* what, int device) {
    Runtime rt;
    host::check_error(rt, (int)e, what, device);
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
    Runtime rt;
    before_ = host::enter_device(rt, device);
}

DeviceGuard::~DeviceGuard() {
    Runtime rt;
    host::leave_device(rt, before_, device_);
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

std::pair<size_t, size_t> memory_info(int device) {
    detail::DeviceGuard guard(device);
    size_t free = 0, total = 0;
    CUDA_CHECK(cudaMemGetInfo(&free, &total));
    return {free, total};
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
