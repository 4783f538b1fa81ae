#!/usr/bin/env bash
# Cross-build the CPU module for aarch64 (Debian's aarch64-linux-gnu-g++, cmake/aarch64-linux-gnu.cmake) and run it
# under qemu-aarch64 with an aarch64 Python: prints the module's SIMD line (NEON selected). tests/install/test_aarch64.py
# runs this and compares its renders with x86-64's.
#
#   scripts/check_aarch64.sh [--install] [BUILD_DIR]      (BUILD_DIR: build/aarch64)
#
# The aarch64 Python is Debian 12's (python3 with numpy, Pillow, zstandard, pytest, scipy and the headers),
# unpacked from Debian's archive into GBVIEWER_AARCH64_ROOT (default ~/.cache/gbviewer/aarch64-root) by
# `debootstrap --foreign` (its first stage: download and unpack, nothing run); --install makes it when missing
# (root, about 930 MB unpacked). qemu-aarch64 -L runs it from there. BUILD_DIR/pkg is a copy of this checkout's gbviewer package (and
# shaders/, assets/, tests/, tools/) with the aarch64 module, and plyfile (pure Python) from this Python. Exit
# status 3, with one line, when a tool or the aarch64 Python is missing (the test skips then), 1 when the build or
# the run fails.
set -euo pipefail
cd "$(dirname "$0")/.."
install=0
if [ "${1:-}" = --install ]; then install=1; shift; fi
BUILD=$(realpath -m "${1:-build/aarch64}")
PY=${PYTHON:-python3}
ROOTFS=${GBVIEWER_AARCH64_ROOT:-${XDG_CACHE_HOME:-$HOME/.cache}/gbviewer/aarch64-root}
missing() { echo "check_aarch64: missing $1: apt-get install $2"; exit 3; }
command -v aarch64-linux-gnu-g++ >/dev/null || missing aarch64-linux-gnu-g++ crossbuild-essential-arm64
command -v qemu-aarch64 >/dev/null || missing qemu-aarch64 qemu-user
command -v cmake >/dev/null || missing cmake cmake

site="$ROOTFS/usr/lib/python3/dist-packages"
if [ ! -d "$site/pytest" ] || [ ! -d "$site/scipy" ]; then
  if [ $install = 0 ]; then
    echo "check_aarch64: no aarch64 Python in $ROOTFS: run scripts/check_aarch64.sh --install (as root) first"
    exit 3
  fi
  [ "$(id -u)" = 0 ] || { echo "check_aarch64: --install runs debootstrap, which needs root"; exit 3; }
  command -v debootstrap >/dev/null || missing debootstrap debootstrap
  tmp="$ROOTFS.tmp"
  rm -rf "$tmp" && mkdir -p "$(dirname "$ROOTFS")"
  echo "check_aarch64: unpacking Debian 12's aarch64 Python into $ROOTFS (debootstrap --foreign)"
  debootstrap --foreign --arch=arm64 --variant=minbase \
    --include=python3,python3-numpy,python3-pil,python3-zstandard,python3-pytest,python3-scipy,libpython3-dev \
    bookworm "$tmp" http://deb.debian.org/debian > "$tmp.log" 2>&1 || { tail -5 "$tmp.log"; exit 1; }
  # the first stage unpacks only the required packages; the others wait in its archive folder
  for deb in "$tmp"/var/cache/apt/archives/*.deb; do dpkg-deb -x "$deb" "$tmp"; done
  rm -f "$tmp"/var/cache/apt/archives/*.deb
  # the BLAS/LAPACK alternatives (made by the packages' postinst, which a foreign unpack does not run)
  lib="$tmp/usr/lib/aarch64-linux-gnu"
  ln -sf blas/libblas.so.3 "$lib/libblas.so.3" && ln -sf lapack/liblapack.so.3 "$lib/liblapack.so.3"
  rm -rf "$ROOTFS" && mv "$tmp" "$ROOTFS" && rm -f "$tmp.log"
fi
run() { env -i PATH=/usr/bin:/bin PYTHONPATH="$BUILD/pkg" qemu-aarch64 -L "$ROOTFS" "$ROOTFS/usr/bin/python3" "$@"; }
ver=$(cd / && run -c 'import sys; print("%d.%d" % sys.version_info[:2])')
host=$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
if [ "$ver" != "$host" ]; then
  echo "check_aarch64: the aarch64 Python is $ver, this one ($PY) $host: run it with a Python $ver (PYTHON=...)"
  exit 3
fi

nb=$("$PY" -m nanobind --cmake_dir)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
# Python.h from the aarch64 root; its pyconfig.h includes <aarch64-linux-gnu/python3.X/pyconfig.h>, found through
# -idirafter after the cross compiler's own headers
cmake -S . -B "$BUILD" "${gen[@]}" --toolchain cmake/aarch64-linux-gnu.cmake -DCMAKE_BUILD_TYPE=Release \
  -DGBVIEWER_CUDA=OFF "${launcher[@]}" -Dnanobind_DIR="$nb" -DPython_EXECUTABLE="$(command -v "$PY")" \
  -DPython_INCLUDE_DIR="$ROOTFS/usr/include/python$ver" -DSKBUILD_SOABI="cpython-${ver/./}-aarch64-linux-gnu" \
  "-DCMAKE_CXX_FLAGS=-idirafter $ROOTFS/usr/include" > "$BUILD.configure.log" 2>&1 ||
  { cat "$BUILD.configure.log"; exit 1; }
cmake --build "$BUILD" -j"${JOBS:-2}" --target _native > "$BUILD.build.log" 2>&1 ||
  { tail -30 "$BUILD.build.log"; exit 1; }

rm -rf "$BUILD/pkg" && mkdir -p "$BUILD/pkg"
cp -r gbviewer shaders assets tests tools "$BUILD/pkg/"  # as in a checkout (tests, tools: for pytest)
find "$BUILD/pkg" \( -name '*.so' -o -name __pycache__ \) -prune -exec rm -rf {} +
cp "$BUILD"/_native.cpython-*-aarch64-linux-gnu.so "$BUILD/pkg/gbviewer/"
plyfile=$("$PY" -c 'import plyfile; print(plyfile.__file__)')
cp -r "$(dirname "$plyfile")"/plyfile* "$BUILD/pkg/"
(cd / && run -c 'import platform, gbviewer as gb
from gbviewer.render import simd_line
print(platform.machine(), simd_line(gb.build_info()))')
