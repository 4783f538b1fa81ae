"""The CPU module's other builds, each configured with CMake here (slow; CI runs them):

- Highway's headers hidden: the configure downloads the pinned release (cmake/highway.cmake) and uses it; a local
  copy (GBVIEWER_HIGHWAY_ARCHIVE) is checked against the pinned SHA-256; with the download off (or a wrong archive)
  the configure stops with one line saying what to do.
- clang++, with Highway from that archive: a module with the vector paths whose renders match this module's.
- GBVIEWER_SCALAR_ONLY=1 and no OpenMP (GBVIEWER_OPENMP=OFF, omp_shim.h): a module that reports both and renders as
  this module's scalar path does.
"""

from __future__ import annotations

import json
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import skip_or_fail
from native_builds import assert_renders_match, build, cmake_env, configure, hidden_highway, run_child, stage_package

from gbviewer.render import compiler_line, simd_line

X86 = platform.machine() in ("x86_64", "AMD64")
HWY = "highway-1.0.3"
NO_HWY_LINE = "gbviewer: Google Highway's headers (hwy/highway.h) not found and GBVIEWER_FETCH_HIGHWAY is off"
SIZE = 96
SCENE = Path(__file__).resolve().parents[2] / "assets" / "fruit_drops_minimal.ply"  # the bundled scene

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed"),
    pytest.mark.skipif(not X86, reason="x86-64's builds (aarch64's: test_aarch64.py)"),
]


def one_line(proc, start: str) -> str:
    lines = [ln for ln in (proc.stdout + proc.stderr).splitlines() if ln.startswith(start)]
    assert len(lines) == 1, proc.stdout + proc.stderr
    return lines[0]


def test_without_highway_and_download_off_fails_with_one_line(tmp_path):
    for how in (["-DGBVIEWER_FETCH_HIGHWAY=OFF"], []):  # the CMake option, the environment variable
        env = cmake_env(GBVIEWER_FETCH_HIGHWAY="OFF") if not how else None
        proc = configure(tmp_path / f"b{len(how)}", *hidden_highway(), *how, env=env)
        assert proc.returncode != 0
        line = one_line(proc, NO_HWY_LINE)
        assert "apt-get install libhwy-dev" in line and "GBVIEWER_HIGHWAY_ARCHIVE=FILE" in line
        assert "GBVIEWER_SCALAR_ONLY=1 pip install ." in line


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """The pinned Highway tarball, as the configure downloads it with Highway hidden (the route of a machine
    without libhwy-dev): the configure says so and compiles against the download."""
    b = tmp_path_factory.mktemp("fetch") / "b"
    proc = configure(b, *hidden_highway())
    if proc.returncode != 0 and "download of Highway" in proc.stdout + proc.stderr:
        skip_or_fail(f"no network for Highway's download: {one_line(proc, 'gbviewer: ')[:300]}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "CPU blend paths scalar, avx2, avx512 (Highway 1.0.3: downloaded)" in proc.stdout
    commands = json.loads((b / "compile_commands.json").read_text())
    blend = next(c["command"] for c in commands if c["file"].endswith("blend_isa.cpp"))
    assert f"-I{b / '_deps' / HWY}" in blend or f"-isystem {b / '_deps' / HWY}" in blend
    return b / "_deps" / f"{HWY}.tar.gz"


def test_a_wrong_archive_fails_with_one_line(tmp_path):
    bad = tmp_path / f"{HWY}.tar.gz"
    bad.write_bytes(b"not highway")
    proc = configure(tmp_path / "b", *hidden_highway(), f"-DGBVIEWER_HIGHWAY_ARCHIVE={bad}")
    assert proc.returncode != 0
    assert "is not Highway 1.0.3's release tarball (SHA-256" in one_line(proc, f"gbviewer: {bad}")


@pytest.mark.skipif(shutil.which("clang++") is None, reason="clang++ is not installed (Debian: clang libomp-dev)")
def test_clang_build_from_the_archive(tmp_path, archive):
    """clang++ (Clang 14 has no _Float16 on x86-64 and no "f16c" in __builtin_cpu_supports: half.h, CPUID) with
    Highway from the archive, no download: the vector paths, the F16C check of its float16 conversion on every
    float, and renders as this module's on the same path."""
    b = tmp_path / "b"
    proc = configure(
        b,
        *hidden_highway(),
        "-DCMAKE_CXX_COMPILER=clang++",
        env=cmake_env(GBVIEWER_HIGHWAY_ARCHIVE=str(archive), GBVIEWER_FETCH_HIGHWAY="OFF"),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"(Highway 1.0.3: the archive {archive})" in proc.stdout
    pkg = stage_package(build(b), tmp_path / "pkg")
    code = "import gbviewer._native as n; print(n.testing.half_mismatches(0, 2**32))"
    half = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        cwd="/",
        env={**cmake_env(), "PYTHONPATH": str(pkg)},
    )
    assert half.returncode == 0 and half.stdout.strip() in ("0", "-1"), half.stdout + half.stderr
    out = tmp_path / "out"
    report = run_child([sys.executable], pkg, out, [SCENE], SIZE, cmake_env(), 300)
    info = report["build"]
    assert info["compiler"].startswith("Clang") and info["simd_built"] == ["scalar", "avx2", "avx512"]
    assert info["simd_selected"] == info["simd_usable"][-1] and set(report["simd"]) == {info["simd_selected"]}
    assert info["openmp"] is None or "_OPENMP" in info["openmp"]
    assert_renders_match(out, [SCENE], SIZE, info["simd_selected"], "clang++ build")


def test_scalar_only_build_without_openmp_reports_both(tmp_path):
    b = tmp_path / "b"
    proc = configure(b, *hidden_highway(), "-DGBVIEWER_OPENMP=OFF", env=cmake_env(GBVIEWER_SCALAR_ONLY="1"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    warnings = " ".join(proc.stderr.split())  # CMake wraps its warnings
    assert "GBVIEWER_SCALAR_ONLY is set" in warnings and "the CPU module renders on one thread" in warnings
    commands = {Path(c["file"]).name: c["command"] for c in json.loads((b / "compile_commands.json").read_text())}
    assert "blend_isa.cpp" not in commands and "-fopenmp" not in commands["frame.cpp"]
    pkg = stage_package(build(b), tmp_path / "pkg")
    report = run_child([sys.executable], pkg, tmp_path / "out", [SCENE], SIZE, cmake_env(), 300)
    info = {"cpu_module": True, **report["build"]}
    assert info["scalar_only"] is True and info["simd_built"] == info["simd_usable"] == ["scalar"]
    assert info["openmp"] is None and "no OpenMP" in compiler_line(info)
    assert "scalar-only build" in simd_line(info)
    assert_renders_match(tmp_path / "out", [SCENE], SIZE, "scalar", "scalar-only, no OpenMP")
