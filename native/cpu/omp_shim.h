// OpenMP's runtime functions, or, in a build without OpenMP (CMakeLists.txt: GBVIEWER_OPENMP=OFF or a compiler
// without it), serial stand-ins: one thread, so every `#pragma omp` region (ignored by the compiler then) runs once on
// the calling thread, which every region here is written to allow (a team of one).
#pragma once

#ifdef _OPENMP
#include <omp.h>
#else
inline int omp_get_max_threads() { return 1; }
inline int omp_get_thread_num() { return 0; }
inline int omp_get_num_threads() { return 1; }
inline void omp_set_num_threads(int) {}
#endif
