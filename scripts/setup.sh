#!/usr/bin/env bash
# Set up gbviewer on a fresh Debian-like machine: system packages (when root with apt-get), a venv in .venv, the
# package with its native module and test dependencies. Safe to run again; it only installs what is missing.
# Without root (or apt-get), scripts/check_system.sh says in one line per missing piece which package provides it;
# the setup stops only when the build cannot succeed (GBVIEWER_SCALAR_ONLY=1 builds without Highway, on purpose).
set -euo pipefail
cd "$(dirname "$0")/.."

# libhwy-dev: Google Highway headers for the vectorised CPU blend; libgl-dev: GL headers for the CUDA backend's
# CUDA-GL interop (the viewer's GPU display path); libegl1,
# libegl-mesa0, libgl1-mesa-dri: headless OpenGL 4.5 (Mesa llvmpipe through EGL) for the glsl backend and its tests;
# glslang-tools: the Khronos reference GLSL front end the tests hold every shader variant to (and whose SPIR-V shows
# the preprocess's `precise`); qemu-user: the tests run the built module on an emulated CPU without AVX, and the
# aarch64 build (crossbuild-essential-arm64; debootstrap for its Python, scripts/check_aarch64.sh) under emulation;
# clang, libomp-dev: the clang++ build test; ccache: the build tests' rebuilds.
APT_PACKAGES=(build-essential cmake python3-venv python3-dev libhwy-dev libgl-dev libegl1 libegl-mesa0 libgl1-mesa-dri
  glslang-tools qemu-user xvfb xauth libglfw3 libxrandr2 libxinerama1 libxcursor1 libxi6  # xvfb..libxi6: the viewer window, tested under Xvfb
  clang libomp-dev ccache crossbuild-essential-arm64 debootstrap)
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  missing=()
  for p in "${APT_PACKAGES[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
else
  echo "setup: not root or no apt-get: installing no system packages, checking what is there"
fi
PY=${PYTHON:-python3}
if ! PYTHON="$PY" "$BASH" scripts/check_system.sh; then  # this same bash
  echo "setup: stopped: install what is missing above (or ask an administrator to) and run this again" >&2
  exit 1
fi

[ -x .venv/bin/python ] || "$PY" -m venv .venv
pip_install() {
  if ! .venv/bin/python -m pip install -q "$@" > .venv/pip.log 2>&1; then
    grep -v "^WARNING: Location" .venv/pip.log >&2
    echo "setup: pip install $* failed" >&2
    exit 1
  fi
}
pip_install --upgrade pip
echo "setup: building and installing gbviewer and its native CPU module (about a minute)"
# dev: the viewer, video and eval extras and the test tools; duplex: torch for Duplex-GS checkpoints; ray: gbviewer
# eval --ray (and their tests)
pip_install ".[dev,duplex,ray]"
