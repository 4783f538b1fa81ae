// The preprocess for one vector instruction set: the stage and a mode's finish (preprocess_range.h) on Highway's
// lanes, 8 splats at a time on x86 (AVX2 and AVX-512: lanes_hwy.h's PreprocessLanes). CMake compiles this file once
// per set, like blend_isa.cpp, and with -ffp-contract=off besides the lane type's mul_rn barrier: no multiply-add is
// fused, so every lane computes what preprocess_splat computes for one splat, bit for bit.
#include "lanes_hwy.h"
#include "preprocess_range.h"

#define GBV_CAT2(a, b) a##b
#define GBV_CAT(a, b) GBV_CAT2(a, b)

namespace gbv {

void GBV_CAT(stage_range_, GBV_ISA_NAME)(const StageJob& job, int64_t begin, int64_t end) {
    stage_range<HWY_NAMESPACE::PreprocessLanes>(job, begin, end);
}

void GBV_CAT(finish_range_, GBV_ISA_NAME)(const FinishJob& job, int64_t begin, int64_t end) {
    finish_range<HWY_NAMESPACE::PreprocessLanes>(job, begin, end);
}

}  // namespace gbv
