// native/cuda/host_logic.h on a stand-in CUDA runtime, compiled with the host compiler by test_cuda_host.py (no
// GPU, no CUDA headers): prints "ok NAME" per case, or "FAIL NAME: why" and exits 1.
#include <cstdio>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "host_logic.h"

using namespace gbv::cuda::host;

struct DeviceFailed : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// A thread and the runtime as the driver sees them: a thread that never chose a device has no context and the
// runtime answers device 0 for it.
struct FakeRuntime {
    bool context = false;
    int current = 0;
    std::map<int, int> set_errors;  // device -> the error cudaSetDevice returns for it
    int sync_result = 0;
    std::vector<int> sets;
    std::map<int, std::string> failed;
    int syncs = 0;

    std::string error_string(int e) { return "error " + std::to_string(e); }
    void clear_error() {}
    bool is_fatal(int e) { return e == 46 || e == 700; }  // cudaErrorDevicesUnavailable, cudaErrorIllegalAddress
    bool out_of_memory(int e) { return e == 2; }
    int synchronize() {
        ++syncs;
        return sync_result;
    }
    int current_device() { return current; }
    [[noreturn]] void fail(int device, const std::string& msg) {
        failed.emplace(device, msg);
        throw DeviceFailed(msg);
    }
    bool has_context() { return context; }
    int set_device(int device) {
        sets.push_back(device);
        const auto it = set_errors.find(device);
        if (it != set_errors.end()) return it->second;
        current = device;
        context = true;
        return 0;
    }
    void check(int e, const char* what, int device) { check_error(*this, e, what, device); }
};

static int failures = 0;

static void expect(bool ok, const char* name, const std::string& why) {
    if (ok) {
        std::printf("ok %s\n", name);
    } else {
        std::printf("FAIL %s: %s\n", name, why.c_str());
        ++failures;
    }
}

static std::string list(const std::vector<int>& v) {
    std::string s = "[";
    for (int x : v) s += std::to_string(x) + " ";
    return s + "]";
}

template <class E, class F>
static bool throws(F&& f) {
    try {
        f();
    } catch (const E&) { return true; }
    return false;
}

int main() {
    {  // a thread that never chose a device: the guard makes device 1 current and does not make device 0 current
        FakeRuntime rt;
        const ThreadDevice before = enter_device(rt, 1);
        leave_device(rt, before, 1);
        expect(rt.sets == std::vector<int>{1}, "guard_on_a_fresh_thread_restores_nothing", "sets " + list(rt.sets));
    }
    {  // a thread that chose device 0 gets it back
        FakeRuntime rt;
        rt.context = true;
        const ThreadDevice before = enter_device(rt, 1);
        leave_device(rt, before, 1);
        expect(rt.sets == (std::vector<int>{1, 0}) && rt.current == 0, "guard_restores_the_chosen_device",
               "sets " + list(rt.sets));
    }
    {  // already on the device: no switch either way
        FakeRuntime rt;
        rt.context = true;
        rt.current = 1;
        leave_device(rt, enter_device(rt, 1), 1);
        expect(rt.sets.empty(), "guard_on_the_same_device_switches_nothing", "sets " + list(rt.sets));
    }
    {  // a fatal error switching to device 1 marks device 1, not the current device 0
        FakeRuntime rt;
        rt.context = true;
        rt.set_errors[1] = 46;
        const bool threw = throws<DeviceFailed>([&] { enter_device(rt, 1); });
        expect(threw && rt.failed.size() == 1 && rt.failed.count(1) &&
                   rt.failed[1].rfind("CUDA device 1 failed: CUDA error in cudaSetDevice: error 46", 0) == 0 &&
                   rt.syncs == 0,
               "failed_switch_marks_the_target_device",
               rt.failed.empty() ? "nothing marked" : "marked " + std::to_string(rt.failed.begin()->first));
    }
    {  // a plain error switching to device 1: no device marked, and device 0 is not asked (not the target)
        FakeRuntime rt;
        rt.context = true;
        rt.set_errors[1] = 101;
        rt.sync_result = 700;  // device 0 would answer with a sticky error of its own
        const bool threw = throws<std::runtime_error>([&] { enter_device(rt, 1); });
        expect(threw && rt.failed.empty() && rt.syncs == 0, "plain_switch_error_marks_nothing",
               "syncs " + std::to_string(rt.syncs) + ", marked " + std::to_string(rt.failed.size()));
    }
    {  // on the current device: an error after which the device no longer synchronises marks the current device
        FakeRuntime rt;
        rt.context = true;
        rt.current = 2;
        rt.sync_result = 700;
        const bool threw = throws<DeviceFailed>([&] { check_error(rt, 9, "kernel", -1); });
        expect(threw && rt.failed.count(2) && rt.failed[2].find("(then error 700)") != std::string::npos,
               "sticky_error_marks_the_current_device", "marked " + std::to_string(rt.failed.size()));
    }
    {  // out of memory: the device stays usable and is not asked
        FakeRuntime rt;
        rt.sync_result = 700;
        const bool threw = throws<std::runtime_error>([&] { check_error(rt, 2, "cudaMalloc", -1); });
        expect(threw && rt.failed.empty() && rt.syncs == 0, "out_of_memory_is_not_fatal", "");
    }
    {  // a stale derived upload (checked against generation 1, scene 2 uploaded since) leaves scene 2's data
        std::vector<std::string> steps;
        const bool threw = throws<std::runtime_error>([&] {
            replace_derived(
                true, 2, 1, "view weights", [&] { steps.push_back("clear"); }, [&] { steps.push_back("copy"); });
        });
        expect(threw && steps.empty(), "stale_derived_upload_keeps_the_data", std::to_string(steps.size()) + " steps");
        steps.clear();
        const bool before_scene = throws<std::runtime_error>([&] {
            replace_derived(false, 0, 0, "cells", [&] { steps.push_back("clear"); }, [&] { steps.push_back("copy"); });
        });
        expect(before_scene && steps.empty(), "derived_upload_before_a_scene_is_refused", "");
        replace_derived(true, 2, 2, "cells", [&] { steps.push_back("clear"); }, [&] { steps.push_back("copy"); });
        expect(steps == (std::vector<std::string>{"clear", "copy"}), "current_derived_upload_clears_then_copies",
               std::to_string(steps.size()) + " steps");
    }
    return failures ? 1 : 0;
}
