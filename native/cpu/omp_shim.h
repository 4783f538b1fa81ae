// OpenMP's runtime functions, or, in a build without OpenMP (CMakeLists.txt: GBVIEWER_OPENMP=OFF or a compiler
// without it), serial stand-ins: one thread, so every `#pragma omp` region (ignored by the compiler then) runs once on
// the calling thread, which every region here is written to allow (a team of one).
#pragma once

#include <algorithm>

#ifdef _OPENMP
#include <omp.h>
#else
inline int omp_get_max_threads() { return 1; }
inline int omp_get_thread_num() { return 0; }
inline int omp_get_num_threads() { return 1; }
inline void omp_set_num_threads(int) {}
#endif

namespace gbv {

// The most threads a team gets (gbviewer.render.types.MAX_THREADS, the bound of RenderSettings.threads): a default
// from OMP_NUM_THREADS beyond it is capped, since libgomp cannot start a team of 100000 (it crashed, or exited).
constexpr int MAX_TEAM = 1024;

// The threads of a team: `threads` when > 0, else OpenMP's default; at most MAX_TEAM.
inline int team(int threads) { return std::min(threads > 0 ? threads : omp_get_max_threads(), MAX_TEAM); }

}  // namespace gbv
