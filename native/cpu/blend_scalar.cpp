// The blend one pixel at a time and the preprocess one splat at a time (Lanes1): the path for CPUs without AVX2 and the reference the vector paths are
// tested against. Built with the baseline flags.
#include "blend_tile.h"
#include "exp_sum.h"
#include "preprocess_range.h"

namespace gbv {

void blend_tile_scalar(const TileJob& job) { blend_tile<Lanes1>(job); }

float exp_sum_scalar(int64_t n) { return exp_sum<Lanes1>(n); }

void stage_range_scalar(const StageJob& job, int64_t begin, int64_t end) { stage_range<Lanes1>(job, begin, end); }

void finish_range_scalar(const FinishJob& job, int64_t begin, int64_t end) { finish_range<Lanes1>(job, begin, end); }

}  // namespace gbv
