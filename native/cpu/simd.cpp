// Run-time choice of the blend's and preprocess's instruction set (x86-64: scalar, avx2, avx512; aarch64: scalar,
// neon). The vector paths are separate translation units built with their own -m flags (cmake/simd.cmake); this file
// is built for the baseline and only calls into them after checking the CPU (and the OS's register state, which
// __builtin_cpu_supports includes) runs them.
#include "simd.h"

#if defined(__x86_64__)
#include <cpuid.h>
#endif

#include <atomic>
#include <cstdlib>
#include <stdexcept>

namespace gbv {
void blend_tile_scalar(const TileJob& job);
float exp_sum_scalar(int64_t n);
void stage_range_scalar(const StageJob& job, int64_t begin, int64_t end);
void finish_range_scalar(const FinishJob& job, int64_t begin, int64_t end);
#ifdef GBV_HAVE_AVX2
void blend_tile_avx2(const TileJob& job);
float exp_sum_avx2(int64_t n);
void stage_range_avx2(const StageJob& job, int64_t begin, int64_t end);
void finish_range_avx2(const FinishJob& job, int64_t begin, int64_t end);
#endif
#ifdef GBV_HAVE_NEON
void blend_tile_neon(const TileJob& job);
float exp_sum_neon(int64_t n);
void stage_range_neon(const StageJob& job, int64_t begin, int64_t end);
void finish_range_neon(const FinishJob& job, int64_t begin, int64_t end);
#endif
#ifdef GBV_HAVE_AVX512
void blend_tile_avx512(const TileJob& job);
float exp_sum_avx512(int64_t n);
void stage_range_avx512(const StageJob& job, int64_t begin, int64_t end);
void finish_range_avx512(const FinishJob& job, int64_t begin, int64_t end);
#endif
}  // namespace gbv

namespace gbv::simd {
namespace {

const Path kScalar{"scalar", blend_tile_scalar, exp_sum_scalar, stage_range_scalar, finish_range_scalar};
#ifdef GBV_HAVE_AVX2
const Path kAvx2{"avx2", blend_tile_avx2, exp_sum_avx2, stage_range_avx2, finish_range_avx2};
#endif
#ifdef GBV_HAVE_NEON
const Path kNeon{"neon", blend_tile_neon, exp_sum_neon, stage_range_neon, finish_range_neon};
#endif
#ifdef GBV_HAVE_AVX512
const Path kAvx512{"avx512", blend_tile_avx512, exp_sum_avx512, stage_range_avx512, finish_range_avx512};
#endif

#if defined(GBV_HAVE_AVX2) || defined(GBV_HAVE_AVX512)
// Everything Highway's AVX2 target is compiled with (its HWY_TARGET_STR_AVX2).
bool cpu_has_avx2() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") &&
           __builtin_cpu_supports("bmi2") && cpu_has_f16c() && __builtin_cpu_supports("sse4.2") &&
           __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("aes");
}
#endif

std::atomic<const Path*> g_current{nullptr};

}  // namespace

#if defined(__x86_64__)
bool cpu_has_f16c() {
    unsigned a, b, c, d;
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx") && __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C);
}
#endif

std::vector<const Path*> built() {
    std::vector<const Path*> out{&kScalar};
#ifdef GBV_HAVE_AVX2
    out.push_back(&kAvx2);
#endif
#ifdef GBV_HAVE_AVX512
    out.push_back(&kAvx512);
#endif
#ifdef GBV_HAVE_NEON
    out.push_back(&kNeon);
#endif
    return out;
}

std::vector<const Path*> supported() {
    std::vector<const Path*> out{&kScalar};
#ifdef GBV_HAVE_NEON
    out.push_back(&kNeon);  // every aarch64 CPU has NEON (Advanced SIMD)
#endif
#ifdef GBV_HAVE_AVX2
    if (cpu_has_avx2()) out.push_back(&kAvx2);
#endif
#ifdef GBV_HAVE_AVX512
    if (cpu_has_avx2() && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
        __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw"))
        out.push_back(&kAvx512);
#endif
    return out;
}

const Path& current() {
    const Path* p = g_current.load();
    if (!p) {
        p = supported().back();
        g_current.store(p);
    }
    return *p;
}

void select(const std::string& name) {
    std::string names;
    for (const Path* p : supported()) {
        if (name == p->name) {
            g_current.store(p);
            return;
        }
        names += names.empty() ? p->name : std::string(", ") + p->name;
    }
    const bool known = name == "scalar" || name == "avx2" || name == "avx512" || name == "neon";
    throw std::invalid_argument("SIMD path '" + name + "' " +
                                (known ? "is not supported by this CPU or build" : "is unknown") +
                                "; available here: " + names);
}

void init_from_env() {
    const char* env = std::getenv("GBVIEWER_SIMD");
    if (!env || !*env) return;
    try {
        select(env);
    } catch (const std::invalid_argument& e) {
        throw std::runtime_error(std::string("GBVIEWER_SIMD=") + env + ": " + e.what());
    }
}

}  // namespace gbv::simd
