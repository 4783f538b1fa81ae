# The CPU module's vector paths: blend_isa.cpp and preprocess_isa.cpp compiled once per instruction set with that
# set's flags (Highway's static target in each), chosen at run time by native/cpu/simd.cpp. Never for the build
# machine's own CPU. x86-64: AVX2 and AVX-512 (Highway's AVX2 and AVX3 targets); aarch64: NEON (Highway's NEON
# target; NEON is in every aarch64 CPU, so it needs no flags and no run-time check). Never silently slow: the build
# has its vector paths or stops with one line (cmake/highway.cmake); GBVIEWER_SCALAR_ONLY (CMake option or
# environment variable, as pip passes it) builds the scalar path on purpose. Sets GBV_ISA_FLAGS for build_info().

option(GBVIEWER_SCALAR_ONLY "Build the CPU module without its vector paths, on purpose" OFF)
if("$ENV{GBVIEWER_SCALAR_ONLY}")
  set(GBVIEWER_SCALAR_ONLY ON)
endif()

# One instruction set's objects, linked into _native; GBV_HAVE_<NAME> tells simd.cpp it is there.
function(gbv_isa name)
  add_library(gbv_blend_${name} OBJECT native/cpu/blend_isa.cpp native/cpu/preprocess_isa.cpp)
  set_target_properties(gbv_blend_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  target_include_directories(gbv_blend_${name} PRIVATE native/include native/cpu ${HWY_INCLUDE_DIR})
  target_compile_definitions(gbv_blend_${name} PRIVATE GBV_ISA_NAME=${name})
  # hidden like the module's own code: nothing of one instruction set is exported or interposable
  target_compile_options(gbv_blend_${name} PRIVATE ${GBV_CPU_FLAGS} ${ARGN} -fvisibility=hidden
                         -fvisibility-inlines-hidden)
  target_sources(_native PRIVATE $<TARGET_OBJECTS:gbv_blend_${name}>)
  string(TOUPPER ${name} upper)
  target_compile_definitions(_native PRIVATE GBV_HAVE_${upper})
endfunction()

# The flags of one of Highway's x86 targets, read from the headers in use (`macro`: HWY_TARGET_STR_AVX2 or _AVX3 of
# hwy/ops/set_macros-inl.h) rather than listed by hand: each release names the features its ops are compiled for
# (1.2 added avx512cd to AVX3, 1.3 evex512 on GCC 14 / Clang 18), and its intrinsics inline only into code built with
# every one of them. This compiler preprocesses the string, so Highway's conditions on the compiler hold as for the
# kernels. Sets `out` to the -m flags, in Highway's order, each once.
function(gbv_hwy_target_flags out macro)
  set(src "${CMAKE_BINARY_DIR}/gbv_hwy_${macro}.cc")
  file(WRITE "${src}" "#include \"hwy/highway.h\"\ngbv_target_string ${macro}\n")
  execute_process(COMMAND ${CMAKE_CXX_COMPILER} -std=c++17 -E -P "-I${HWY_INCLUDE_DIR}" "${src}"
                  OUTPUT_VARIABLE pp ERROR_VARIABLE err RESULT_VARIABLE rc)
  string(REGEX MATCH "gbv_target_string[^\n]*" line "${pp}")
  string(REGEX MATCHALL "\"[^\"]*\"" parts "${line}")
  string(REPLACE "\"" "" features "${parts}")
  string(REPLACE ";" "" features "${features}")
  string(REPLACE "," ";" features "${features}")
  list(FILTER features EXCLUDE REGEX "^$")
  if(NOT rc EQUAL 0 OR NOT features)
    string(REPLACE "\n" " " err "${err}")
    gbv_fail("gbviewer: could not read ${macro} from Highway's headers in ${HWY_INCLUDE_DIR} with "
             "${CMAKE_CXX_COMPILER} (exit ${rc}: ${err})")
  endif()
  list(REMOVE_DUPLICATES features)
  list(TRANSFORM features PREPEND "-m")
  set(${out} ${features} PARENT_SCOPE)
endfunction()

set(GBV_ISA_FLAGS "")
set(GBV_X86 "x86_64|AMD64|amd64")
set(GBV_ARM64 "aarch64|arm64|ARM64")
if(GBVIEWER_SCALAR_ONLY)
  message(WARNING "gbviewer: GBVIEWER_SCALAR_ONLY is set: the CPU module has only its scalar path (3-5x slower "
                  "blend); gbviewer.build_info() reports it")
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "${GBV_X86}|${GBV_ARM64}")
  include(${CMAKE_CURRENT_LIST_DIR}/highway.cmake)
  # the vector preprocess fuses no multiply-add (bit-identical to the scalar one, as the module's -ffp-contract=off)
  set_source_files_properties(native/cpu/preprocess_isa.cpp PROPERTIES COMPILE_OPTIONS -ffp-contract=off)
  if(CMAKE_SYSTEM_PROCESSOR MATCHES "${GBV_X86}")
    gbv_hwy_target_flags(avx2 HWY_TARGET_STR_AVX2)
    gbv_hwy_target_flags(avx3 HWY_TARGET_STR_AVX3)
    list(REMOVE_ITEM avx3 ${avx2})
    gbv_isa(avx2 ${avx2})
    gbv_isa(avx512 ${avx2} ${avx3})
    string(JOIN " " GBV_ISA_FLAGS "avx2:" ${avx2} "avx512: +" ${avx3})
    set(paths "avx2, avx512")
  else()
    # SVE is not built: the kernels size their lane arrays at compile time (gbv/lanes.h) and SVE's vectors have a
    # length known only at run time.
    gbv_isa(neon)
    # Highway's own switch for "no run-time dispatch on Arm": its NEON ops then carry no target("+crypto")
    # attribute (which would need AES in every aarch64 CPU and cannot be inlined into the baseline-built kernels).
    target_compile_definitions(gbv_blend_neon PRIVATE TOOLCHAIN_MISS_SYS_AUXV_H)
    # GCC 12 (aarch64) warns that lanes of the stage's lane structs may be read uninitialised: every lane is
    # written (preprocess_range.h loads all N before reading any); x86-64's build of the same code does not warn.
    target_compile_options(gbv_blend_neon PRIVATE -Wno-maybe-uninitialized)
    set(GBV_ISA_FLAGS "neon: (baseline)")
    set(paths "neon")
  endif()
  # Highway's version (hwy/highway.h until 1.0, hwy/base.h since), for build_info()
  set(GBV_HWY_VERSION_FOUND "")
  foreach(part MAJOR MINOR PATCH)
    file(STRINGS "${HWY_INCLUDE_DIR}/hwy/highway.h" line REGEX "^#define HWY_${part} +[0-9]+")
    if(NOT line AND EXISTS "${HWY_INCLUDE_DIR}/hwy/base.h")
      file(STRINGS "${HWY_INCLUDE_DIR}/hwy/base.h" line REGEX "^#define HWY_${part} +[0-9]+")
    endif()
    string(REGEX REPLACE ".* ([0-9]+)$" "\\1" number "${line}")
    list(APPEND GBV_HWY_VERSION_FOUND "${number}")
  endforeach()
  string(JOIN "." GBV_HWY_VERSION_FOUND ${GBV_HWY_VERSION_FOUND})
  message(STATUS "gbviewer: CPU blend paths scalar, ${paths} (Highway ${GBV_HWY_VERSION_FOUND}: ${GBV_HWY_SOURCE})")
else()
  message(WARNING "gbviewer: no vector paths for ${CMAKE_SYSTEM_PROCESSOR}: the CPU blend has only its scalar path")
endif()
