#!/usr/bin/env bash
# Set up gbviewer on a fresh Debian-like machine: system packages (when root with apt-get), a venv in .venv, the
# package with its native module. Safe to run again; it only installs what is missing.
#   scripts/setup.sh         what the viewer and its main job need: the package with its viewer and video extras
#   scripts/setup.sh --dev   also what the tests need: the dev extra, Ray, and torch for Duplex-GS checkpoints where
#                            a CPU build of it is at hand (scripts/pick_torch.py says in one line where none is)
# Without root (or apt-get), scripts/check_system.sh says in one line per missing piece which package provides it;
# the setup stops only when the build cannot succeed (GBVIEWER_SCALAR_ONLY=1 builds without Highway, on purpose).
set -euo pipefail
cd "$(dirname "$0")/.."
DEV=0
case "${1:-}" in
  "") ;;
  --dev) DEV=1 ;;
  *) echo "setup: unknown option ${1}: expected nothing (the viewer) or --dev (the tests too)" >&2; exit 2 ;;
esac

# build-essential..python3-dev: the build; libhwy-dev: Google Highway headers for the vectorised CPU blend;
# libgl-dev: GL headers for the CUDA backend's CUDA-GL interop (the viewer's GPU display path); libegl1,
# libegl-mesa0, libgl1-mesa-dri: headless OpenGL 4.5 (Mesa llvmpipe through EGL) for the glsl backend; libglfw3 and
# the X libraries: the viewer window.
APT_PACKAGES=(build-essential cmake python3-venv python3-dev libhwy-dev libgl-dev libegl1 libegl-mesa0
  libgl1-mesa-dri libglfw3 libxrandr2 libxinerama1 libxcursor1 libxi6)
# The tests only: glslang-tools, the Khronos reference GLSL front end every shader variant is held to; qemu-user, the
# built module on an emulated CPU without AVX and the aarch64 build under emulation (crossbuild-essential-arm64;
# debootstrap for its Python and for scripts/check_distro.sh); xvfb, xauth: the viewer window under test; clang,
# libomp-dev: the clang++ build test; ccache: the build tests' rebuilds.
[ $DEV = 1 ] && APT_PACKAGES+=(glslang-tools qemu-user xvfb xauth clang libomp-dev ccache crossbuild-essential-arm64
  debootstrap)
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
if ! PYTHON="$PY" GBVIEWER_SETUP_DEV=$DEV "$BASH" scripts/check_system.sh; then  # this same bash
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
if [ $DEV = 0 ]; then
  pip_install ".[viewer,video]"
  exit 0
fi
# dev: the viewer, video and eval extras and the test tools; ray: gbviewer eval --ray (and its tests)
pip_install ".[dev,ray]"
# duplex: torch for Duplex-GS checkpoints, only as a CPU build (the package index's own is a CUDA build of gigabytes)
if torch=$(.venv/bin/python scripts/pick_torch.py); then
  mapfile -t torch_args <<<"$torch"
  pip_install "${torch_args[@]}"
fi
