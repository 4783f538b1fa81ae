#!/usr/bin/env bash
# Check what building and testing gbviewer needs, without root and without installing anything: one line per
# missing piece, naming the Debian/Ubuntu package that provides it. Exit status 1 when something the build needs is
# missing (Highway's headers count only with GBVIEWER_FETCH_HIGHWAY=OFF: else the build downloads them, and
# GBVIEWER_SCALAR_ONLY=1 builds without), else 0; what only some tests need (EGL/Mesa, Xvfb, GLFW,
# glslangValidator, qemu-user, clang, the aarch64 cross tools) is listed and the setup goes on without it.
# Uses only bash builtins besides the tools it checks (it must run where little is installed).
set -uo pipefail
PY=${PYTHON:-python3}
CXX_BIN=${CXX:-c++}
need_missing=0
need() { echo "setup: missing $1: apt-get install $2 (the build needs it)"; need_missing=1; }
want() { echo "setup: missing $1: apt-get install $2 ($3 skip without it)"; }

command -v "$CXX_BIN" >/dev/null || need "a C++ compiler ($CXX_BIN)" build-essential
command -v cmake >/dev/null || need cmake cmake
if ! command -v "$PY" >/dev/null; then
  need "Python 3 ($PY)" python3
else
  "$PY" -c "import sysconfig, os, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()['include'], \
'Python.h')))" 2>/dev/null || need "the Python headers (Python.h for $PY)" python3-dev
  "$PY" -c "import ensurepip, venv" 2>/dev/null || need "Python's venv module (with ensurepip)" python3-venv
fi

# Google Highway's headers, where the compiler looks (CPATH included), else in the usual include directories.
hwy=0
if command -v "$CXX_BIN" >/dev/null; then
  "$CXX_BIN" -x c++ -fsyntax-only - <<<'#include <hwy/highway.h>' >/dev/null 2>&1 && hwy=1
else
  for d in /usr/include /usr/local/include; do [ -e "$d/hwy/highway.h" ] && hwy=1; done
fi
if [ $hwy = 0 ]; then
  case "${GBVIEWER_SCALAR_ONLY:-}" in
    1|ON|on|YES|yes|TRUE|true)
      echo "setup: WARNING: Google Highway's headers are missing and GBVIEWER_SCALAR_ONLY=1: building the CPU" \
           "module scalar-only, its blend 3-5x slower (apt-get install libhwy-dev for the vector paths)" ;;
    *) case "${GBVIEWER_FETCH_HIGHWAY:-ON}" in
         0|OFF|off|NO|no|FALSE|false)
           need "Google Highway's headers (hwy/highway.h; the CPU module's vector paths; GBVIEWER_FETCH_HIGHWAY is off)" \
                "libhwy-dev, or set GBVIEWER_SCALAR_ONLY=1 for a slower scalar-only build" ;;
         *) echo "setup: note: Google Highway's headers (hwy/highway.h) are not installed: the build downloads the" \
                 "pinned Highway 1.0.3 (needs the network; apt-get install libhwy-dev to use the system's)" ;;
       esac ;;
  esac
fi

libs=$( (/sbin/ldconfig -p || ldconfig -p) 2>/dev/null)
[[ $libs == *libEGL.so.1* && $libs == *libEGL_mesa.so.0* ]] ||
  want "headless OpenGL (EGL + Mesa)" "libegl1 libegl-mesa0 libgl1-mesa-dri" "the glsl backend and its GL tests"
[[ $libs == *libglfw.so.3* ]] || want GLFW libglfw3 "the viewer and its window tests"
# what only the tests need: checked unless the setup is for the viewer alone (scripts/setup.sh without --dev)
if [ "${GBVIEWER_SETUP_DEV:-1}" = 1 ]; then
  command -v Xvfb >/dev/null || want Xvfb "xvfb xauth" "the viewer window tests"
  command -v glslangValidator >/dev/null || want glslangValidator glslang-tools "the shader reference tests"
  command -v qemu-x86_64 >/dev/null || want qemu-x86_64 qemu-user "the emulated-older-CPU tests"
  command -v clang++ >/dev/null || want clang++ "clang libomp-dev" "the clang++ build test"
  command -v aarch64-linux-gnu-g++ >/dev/null ||
    want aarch64-linux-gnu-g++ crossbuild-essential-arm64 "the aarch64 tests"
  command -v qemu-aarch64 >/dev/null || want qemu-aarch64 qemu-user "the aarch64 tests"
  command -v debootstrap >/dev/null || want debootstrap debootstrap "the aarch64 and Debian 13 tests (their roots)"
fi
exit $need_missing
