#!/usr/bin/env bash
# One GPU session: build gbviewer's native modules (CPU and CUDA) from this checkout with what the machine has
# (nothing is downloaded), then run everything only a GPU can check and write OUT_DIR/report.txt and report.json
# (bench/gpu_session.py lists the pieces). At most 8 minutes in all; every missing piece is one line of the report.
#
#   bash bench/gpu_session.sh OUT_DIR [SCENES_DIR] [--no-gpu]
#
# SCENES_DIR: default ./shared/scenes, else ../shared/scenes, else the bundled scene alone (the report says which).
# --no-gpu (and any machine without a usable CUDA device): checks only that the pieces' files exist and reports
# each GPU piece as "no GPU" (tests/bench/test_gpu_session.py runs it so in CI). Environment: PYTHON (default: the
# checkout's .venv, else python3), GBV_WHEELHOUSE (a folder of wheels to install missing Python packages from,
# offline), GBV_SESSION_SECONDS (default 470).
set -uo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
START=$(date +%s)
DEADLINE=$((START + ${GBV_SESSION_SECONDS:-470}))
OUT="" SCENES="" NO_GPU=""
for arg in "$@"; do
  case "$arg" in
    --no-gpu) NO_GPU=--no-gpu ;;
    *) if [ -z "$OUT" ]; then OUT=$arg; else SCENES=$arg; fi ;;
  esac
done
[ -n "$OUT" ] || { echo "usage: bash bench/gpu_session.sh OUT_DIR [SCENES_DIR] [--no-gpu]" >&2; exit 2; }
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

# Python packages the driver needs; installed from GBV_WHEELHOUSE when given (pip cannot reach an index here).
missing=$("$PY" - <<'EOF'
import importlib.util
need = ["numpy", "plyfile", "PIL", "zstandard", "moderngl", "pytest", "scipy", "hypothesis", "nanobind"]
print(" ".join(n for n in need if importlib.util.find_spec(n) is None))
EOF
)
if [ -n "$missing" ] && [ -n "${GBV_WHEELHOUSE:-}" ]; then
  "$PY" -m pip install -q --no-index --find-links "$GBV_WHEELHOUSE" -e "$REPO[test]" > "$OUT/pip.log" 2>&1 \
    || echo "gpu_session: offline install from $GBV_WHEELHOUSE failed (see pip.log)" >&2
fi

# Build (unless --no-gpu): both modules for this interpreter, CUDA for the local GPU only, into build/gpu-session.
build() {
  if [ -n "$NO_GPU" ]; then echo "no GPU: --no-gpu given, not built"; return; fi
  if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L >/dev/null 2>&1; then
    echo "no GPU: nvidia-smi finds no device, not built"; return
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

if ! "$PY" -c "import numpy" 2>/dev/null; then
  fallback_report "$PY lacks numpy (missing: $missing) and no GBV_WHEELHOUSE to install it from"
  exit 1
fi
timeout $((DEADLINE - $(date +%s) + 5)) "$PY" "$REPO/bench/gpu_session.py" "$OUT" ${SCENES:+--scenes "$SCENES"} \
  $NO_GPU --deadline "$DEADLINE" --build-log "$BUILD_LOG"
status=$?
[ -s "$OUT/report.txt" ] || fallback_report "bench/gpu_session.py exited $status without a report"
cat "$OUT/report.txt"
exit $status
