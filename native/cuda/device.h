// CUDA error handling and device selection for the driver's files (nvcc only). An error that leaves the device
// usable (out of memory, a bad launch configuration) throws std::runtime_error; one that poisons the CUDA context
// (a fault in a kernel, a watchdog timeout, the device lost) throws DeviceFailed and marks the device failed for
// the rest of the process (availability() and new renderers then refuse it).
#pragma once

#include <cuda_runtime.h>

#include <string>
#include <utility>

#include "host_logic.h"
#include "renderer.h"

namespace gbv::cuda::detail {

// Whether e is one of CUDA's sticky errors or says the device is gone (no need to ask the device).
bool is_fatal(cudaError_t e);

// Throws for e != cudaSuccess: DeviceFailed when e is fatal or the device no longer answers a synchronise (the
// device is then marked failed: `device`, the one the operation targeted, else the current one), else
// std::runtime_error naming `what` (the error cleared). host::check_error decides.
void check(cudaError_t e, const char* what, int device = -1);
#define CUDA_CHECK(x) ::gbv::cuda::detail::check((x), #x)

// After each kernel launch or CUB call: a launch error names the kernel. Debug builds (no NDEBUG) also wait for it,
// so that a fault inside a kernel is reported with that kernel's name instead of at a later call.
void launched(const char* kernel);

// The reason `device` failed in this process ("" while it has not).
std::string failure(int device);

// The device's name if it can run the kernels (sm_75 or newer, not failed), else a reason.
std::pair<bool, std::string> usable(int device);

// Makes `device` current on this thread while it lives and restores the device the thread had chosen after (the
// runtime's current device is per thread: a renderer must not change its callers'; host::leave_device says what
// is restored on a thread that had chosen none).
class DeviceGuard {
  public:
    explicit DeviceGuard(int device);
    ~DeviceGuard();
    DeviceGuard(const DeviceGuard&) = delete;
    DeviceGuard& operator=(const DeviceGuard&) = delete;

  private:
    host::ThreadDevice before_;
    int device_;
};

}  // namespace gbv::cuda::detail
