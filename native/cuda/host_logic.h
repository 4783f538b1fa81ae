// Host-side decisions of the CUDA driver (device.cu, renderer.cu), written against the few runtime calls they
// make (the template parameter Rt) and free of CUDA headers, so that tests/render/test_cuda_host.py compiles and
// runs them with the host compiler on a stand-in runtime: which device an error marks failed, what a device guard
// restores, and the order of a derived upload's steps.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace gbv::cuda::host {

// Rt's error calls: std::string error_string(int); void clear_error() (a non-sticky error); bool is_fatal(int);
// bool out_of_memory(int); int synchronize() (the current device); int current_device() (-1 when unknown);
// [[noreturn]] void fail(int device, const std::string&) (marks `device` failed, throws DeviceFailed).
// Code 0 is success.
//
// Throws for e != 0: std::runtime_error naming `what` when the device stays usable, else (e fatal, or the device
// no longer answers a synchronise) Rt::fail on the device the operation targeted: `target`, or the current device
// when target < 0. A failed switch to another device is that device's error; the synchronise that asks whether
// the error stuck is made only where the target is current (it waits on the current device).
template <class Rt>
void check_error(Rt& rt, int e, const char* what, int target) {
    if (e == 0) return;
    std::string msg = std::string("CUDA error in ") + what + ": " + rt.error_string(e);
    rt.clear_error();
    const int current = rt.current_device();
    const int device = target >= 0 ? target : current;
    bool fatal = rt.is_fatal(e);
    if (!fatal && !rt.out_of_memory(e) && device == current) {
        const int probe = rt.synchronize();  // a sticky error shows here too
        if (probe != 0 && !rt.out_of_memory(probe)) {
            fatal = true;
            msg += " (then " + rt.error_string(probe) + ")";
        }
    }
    if (!fatal) throw std::runtime_error(msg);
    rt.fail(device, "CUDA device " + std::to_string(device) + " failed: " + msg);
}

// The calling thread's device before a guard: whether the thread had a current CUDA context (one that never chose
// a device, or used the runtime, has none) and, if so, its device.
struct ThreadDevice {
    bool had_context = false;
    int device = -1;
};

// Rt's device calls: bool has_context(); int current_device(); int set_device(int) (an error code);
// void check(int code, const char* what, int device) (check_error with that target).
//
// Makes `device` current (an error is `device`'s); returns what to restore.
template <class Rt>
ThreadDevice enter_device(Rt& rt, int device) {
    ThreadDevice before;
    before.had_context = rt.has_context();
    before.device = before.had_context ? rt.current_device() : -1;
    if (!before.had_context || before.device != device) rt.check(rt.set_device(device), "cudaSetDevice", device);
    return before;
}

// Puts back the device a thread had chosen. A thread that had none keeps `device`: making the runtime's default
// (device 0) current again would create a context there (memory on GPU 0; on an exclusive-process GPU 0 used by
// another process, a pending error that the next check would pin on this renderer's device).
template <class Rt>
void leave_device(Rt& rt, const ThreadDevice& before, int device) noexcept {
    if (before.had_context && before.device >= 0 && before.device != device && rt.set_device(before.device) != 0)
        rt.clear_error();
}

// Refuses a derived upload (view weights, cells) whose arrays were checked against another scene than the one
// uploaded now (`generation`), or made before any scene.
inline void check_generation(bool has_scene, uint64_t current, uint64_t generation, const char* what) {
    if (!has_scene) throw std::runtime_error(std::string("CUDA renderer: upload a scene before its ") + what);
    if (generation != current)
        throw std::runtime_error(std::string("CUDA renderer: another scene was uploaded while its ") + what +
                                 " were checked");
}

// A derived upload of the scene `generation`: checked first, so that a stale call leaves the current scene's data
// as it is; then the old data cleared, so that a copy failing part way leaves none; then copied.
template <class Clear, class Copy>
void replace_derived(bool has_scene, uint64_t current, uint64_t generation, const char* what, Clear&& clear,
                     Copy&& copy) {
    check_generation(has_scene, current, generation, what);
    clear();
    copy();
}

}  // namespace gbv::cuda::host
