// The SIMD paths of the CPU blend and preprocess and the choice between them: the widest one the CPU runs, unless
// GBVIEWER_SIMD=scalar|avx2|avx512|neon (read when the module loads) or set_simd() names another.
#pragma once

#include <string>
#include <vector>

#include "blend_tile.h"
#include "preprocess_range.h"

namespace gbv::simd {

struct Path {
    const char* name;
    BlendTileFn blend_tile;
    float (*exp_sum)(int64_t);
    StageFn stage;  // the per-camera stage of a range of splats (preprocess_range.h)
    FinishFn finish;  // a mode's finish of it
};

std::vector<const Path*> built();  // paths in this build
std::vector<const Path*> supported();  // paths this build and CPU can run, best last
const Path& current();  // the path renders use now
void select(const std::string& name);  // throws std::invalid_argument naming the paths available
void init_from_env();  // GBVIEWER_SIMD, when set
#if defined(__x86_64__)
// F16C (and the AVX state its VEX encoding needs), read from CPUID: Clang 14's __builtin_cpu_supports has no "f16c"
bool cpu_has_f16c();
#endif

}  // namespace gbv::simd
