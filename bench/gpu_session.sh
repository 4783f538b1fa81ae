#!/usr/bin/env bash
# One GPU session: make sure gbviewer and its test tools import (else install them into the checkout's own venv,
# .venv), build gbviewer's native modules (CPU and CUDA) from this checkout where a CUDA device is, then run every
# check the machine can run and write OUT_DIR/report.txt and report.json (bench/gpu_session.py lists the pieces).
# At most 8 minutes in all; every piece that cannot run is one line of the report saying why.
#
#   bash bench/gpu_session.sh OUT_DIR [SCENES_DIR] [--no-gpu] [--pieces NAME,NAME...]
#
# SCENES_DIR: default ./shared/scenes, else ../shared/scenes, else the bundled scene alone (the report says which).
# --no-gpu (and any machine without a usable CUDA device): no CUDA build, each CUDA piece reported as "no GPU";
# the GLSL pieces still run on the machine's EGL driver (Mesa llvmpipe included). --pieces: only those pieces
# (bench/gpu_session.py's names), the others reported as not selected. Exit 0 unless a piece failed.
# Environment: PYTHON (default: the checkout's .venv, else python3), GBV_WHEELHOUSE (a folder of wheels to install
# from offline; without it pip's index is used), GBV_SESSION_SECONDS (default 470).
set -uo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
START=$(date +%s)
DEADLINE=$((START + ${GBV_SESSION_SECONDS:-470}))
OUT="" SCENES="" NO_GPU="" PIECES=()
while [ $# -gt 0 ]; do
  case "$1" in
    --no-gpu) NO_GPU=--no-gpu ;;
    --pieces) PIECES=(--pieces "${2:-}"); shift ;;
    *) if [ -z "$OUT" ]; then OUT=$1; else SCENES=$1; fi ;;
  esac
  shift
done
USAGE="usage: bash bench/gpu_session.sh OUT_DIR [SCENES_DIR] [--no-gpu] [--pieces NAME,NAME...]"
[ -n "$OUT" ] || { echo "$USAGE" >&2; exit 2; }
mkdir -p "$OUT" || { echo "gpu_session: cannot create $OUT" >&2; exit 2; }
OUT=$(cd "$OUT" && pwd)
if [ -x "$REPO/.venv/bin/python" ]; then PY=${PYTHON:-$REPO/.venv/bin/python}; else PY=${PYTHON:-python3}; fi
BUILD_LOG="$OUT/build.txt"

# A report without Python's help, for when the driver itself cannot run: one line per piece.
fallback_report() {
  local why=$1
  {
    echo "build: $(cat "$BUILD_LOG" 2>/dev/null || echo 'not attempted')"
    for piece in paths "cuda tests" "cuda vs cpu" "glsl on the EGL driver" "glsl vs cpu" "display path + interop" \
                 timings; do
      echo "$piece: skipped: $why"
    done
  } > "$OUT/report.txt"
  "$PY" - "$OUT" "$why" <<'EOF' 2>/dev/null || printf '{"pieces": [], "error": "%s"}\n' "$why" > "$OUT/report.json"
import json, sys
out, why = sys.argv[1], sys.argv[2]
pieces = [dict(name=l.split(": ", 1)[0], status=l.split(": ", 1)[1], detail="", data=None)
          for l in open(f"{out}/report.txt").read().splitlines()]
json.dump(dict(pieces=pieces, error=why), open(f"{out}/report.json", "w"), indent=1)
EOF
  cat "$OUT/report.txt"
}

command -v "$PY" >/dev/null 2>&1 || { PY=true; fallback_report "no Python interpreter ($PYTHON)"; exit 1; }

# What the driver and the test files import, checked outside the checkout (whose gbviewer/ has no compiled module
# unless a session built one): missing pieces are installed into the checkout's own venv, .venv (made from $PY if
# absent), from GBV_WHEELHOUSE offline when given, else from pip's index.
missing_packages() {
  (cd / && "$1" - "$REPO" <<'EOF'
import importlib.util, pathlib, sys
need = ["numpy", "plyfile", "PIL", "zstandard", "moderngl", "rich", "platformdirs", "pytest", "scipy", "hypothesis",
        "nanobind"]
missing = [n for n in need if importlib.util.find_spec(n) is None]
if not any(pathlib.Path(sys.argv[1], "gbviewer").glob("_native*")) and importlib.util.find_spec("gbviewer") is None:
    missing.append("gbviewer")
print(" ".join(missing))
EOF
  ) 2>/dev/null || echo "(the interpreter does not run)"
}
missing=$(missing_packages "$PY")
if [ -n "$missing" ]; then
  VENV="$REPO/.venv"
  [ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV" > "$OUT/pip.log" 2>&1
  index=()
  [ -n "${GBV_WHEELHOUSE:-}" ] && index=(--no-index --find-links "$GBV_WHEELHOUSE")
  echo "gpu_session: $PY lacks $missing: installing gbviewer[dev] into $VENV ${index[*]:+from $GBV_WHEELHOUSE}"
  if [ -x "$VENV/bin/python" ] && "$VENV/bin/python" -m pip install -q "${index[@]}" "$REPO[dev]" >> "$OUT/pip.log" 2>&1
  then
    PY=$VENV/bin/python
    missing=$(missing_packages "$PY")
  else
    echo "gpu_session: installing into $VENV failed (see $OUT/pip.log): $(grep -m1 -i error "$OUT/pip.log")" >&2
  fi
fi

# Build (unless --no-gpu): both modules for this interpreter, CUDA for the local GPU only, into build/gpu-session.
build() {
  if [ -n "$NO_GPU" ]; then echo "no GPU: --no-gpu given, the modules not built"; return; fi
  if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L >/dev/null 2>&1; then
    echo "no GPU: nvidia-smi finds no device, the modules not built"; return
  fi
  local nvcc
  nvcc=$(command -v nvcc || ls /usr/local/cuda/bin/nvcc 2>/dev/null || true)
  for tool in cmake c++; do
    command -v "$tool" >/dev/null 2>&1 || { echo "failed: no $tool here: the modules cannot be built"; return; }
  done
  [ -n "$nvcc" ] || { echo "failed: no nvcc (CUDA toolkit) on this machine: the CUDA module cannot be built"; return; }
  local nbdir
  nbdir=$("$PY" -m nanobind --cmake_dir 2>/dev/null) || { echo "failed: $PY has no nanobind: cannot build"; return; }
  local gen=() bdir="$REPO/build/gpu-session"
  command -v ninja >/dev/null 2>&1 && gen=(-G Ninja)
  if ! cmake -S "$REPO" -B "$bdir" -DCMAKE_BUILD_TYPE=Release -DGBVIEWER_CUDA=ON -DCMAKE_CUDA_COMPILER="$nvcc" \
      -DCMAKE_CUDA_ARCHITECTURES=native -DPython_EXECUTABLE="$(command -v "$PY")" -Dnanobind_DIR="$nbdir" \
      "${gen[@]}" > "$OUT/cmake.log" 2>&1; then
    echo "failed: cmake configure: $(grep -m1 -i error "$OUT/cmake.log")"; return
  fi
  if ! timeout $((DEADLINE - $(date +%s) - 240)) cmake --build "$bdir" -j "$(nproc)" > "$OUT/build.log" 2>&1; then
    echo "failed: build (see build.log): $(grep -m1 -i 'error' "$OUT/build.log")"; return
  fi
  cp "$bdir"/_native*.so "$REPO/gbviewer/"
  local spills
  spills=$(grep -c "spill\|Local memory" "$OUT/build.log")
  echo "ok: built in $(( $(date +%s) - START )) s, $("$nvcc" --version | tail -1); ptxas spill/lmem warnings: $spills"
}
build > "$BUILD_LOG"
echo "gpu_session: build: $(cat "$BUILD_LOG")"

# The tests look for the shared scenes beside the checkout (../shared); a copied checkout may hold them inside.
if [ -d "$REPO/shared/scenes" ] && [ ! -e "$REPO/../shared" ]; then
  ln -s "$REPO/shared" "$REPO/../shared" 2>/dev/null
fi

if [ -n "$missing" ]; then
  fallback_report "$PY lacks $missing and installing it failed (pip.log)"
  exit 1
fi
timeout $((DEADLINE - $(date +%s) + 5)) "$PY" "$REPO/bench/gpu_session.py" "$OUT" ${SCENES:+--scenes "$SCENES"} \
  $NO_GPU "${PIECES[@]}" --deadline "$DEADLINE" --build-log "$BUILD_LOG"
status=$?
[ -s "$OUT/report.txt" ] || fallback_report "bench/gpu_session.py exited $status without a report"
cat "$OUT/report.txt"
exit $status
