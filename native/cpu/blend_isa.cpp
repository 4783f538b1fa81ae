// The blend for one vector instruction set. CMake compiles this file once per set (AVX2, AVX-512) with that set's -m
// flags and GBV_ISA_NAME, so Highway's static target is that set and the entry points are blend_tile_<name> and
// exp_sum_<name>. Everything here has internal linkage or lives in Highway's per-target namespace, so no code
// built for one set can be merged into another's (or the baseline's) by the linker.
#include "blend_tile.h"
#include "exp_sum.h"
#include "lanes_hwy.h"

#define GBV_CAT2(a, b) a##b
#define GBV_CAT(a, b) GBV_CAT2(a, b)

namespace gbv {

void GBV_CAT(blend_tile_, GBV_ISA_NAME)(const TileJob& job) { blend_tile<HWY_NAMESPACE::BlendLanes>(job); }

float GBV_CAT(exp_sum_, GBV_ISA_NAME)(int64_t n) { return exp_sum<HWY_NAMESPACE::LanesHwy>(n); }

}  // namespace gbv
