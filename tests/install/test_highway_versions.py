"""The CPU module against every Highway release a user can have (slow; CI runs it): 1.0.3 is the build under test
(Debian 12's libhwy-dev, or the pinned download); 1.1, 1.2 (Debian 13's) and the newest are fetched, checked against
their SHA-256 and built with the flags their own target strings name (cmake/simd.cmake), and each module's renders on
its selected path match this module's."""

from __future__ import annotations

import json
import platform
import shutil
import sys
from pathlib import Path

import pytest
from helpers import HOST_ONLY, skip_or_fail
from native_builds import (
    HIGHWAY_RELEASES,
    assert_renders_match,
    build,
    cmake_env,
    configure,
    fetch_highway,
    hidden_highway,
    run_child,
    stage_package,
)

SIZE = 96
SCENE = Path(__file__).resolve().parents[2] / "assets" / "fruit_drops_minimal.ply"
# what each release's AVX3 target needs beyond AVX2 on GCC 12 (hwy/ops/set_macros-inl.h: 1.2 added avx512cd)
AVX3_NEEDS = {
    "1.1.0": {"-mavx512f", "-mavx512vl", "-mavx512dq", "-mavx512bw"},
    "1.2.0": {"-mavx512f", "-mavx512cd", "-mavx512vl", "-mavx512dq", "-mavx512bw"},
    "1.3.0": {"-mavx512f", "-mavx512cd", "-mavx512vl", "-mavx512dq", "-mavx512bw"},
}

pytestmark = [
    pytest.mark.slow,
    HOST_ONLY,
    pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed"),
    pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86-64's AVX targets"),
]


@pytest.mark.parametrize("version", sorted(HIGHWAY_RELEASES))
def test_builds_and_renders_with_highway(version, tmp_path):
    headers = fetch_highway(version, tmp_path / "hwy")
    if isinstance(headers, str) and version == "1.1.0":
        pytest.skip(f"{headers} (1.1.0 is published on GitHub only, not in Debian's archive)")
    if isinstance(headers, str):
        skip_or_fail(headers)
    b = tmp_path / "b"
    proc = configure(b, *hidden_highway(), f"-DHWY_INCLUDE_DIR={headers}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"CPU blend paths scalar, avx2, avx512 (Highway {version}: installed, {headers})" in proc.stdout
    commands = json.loads((b / "compile_commands.json").read_text())
    avx512 = next(
        c["command"] for c in commands if c["file"].endswith("blend_isa.cpp") and "gbv_blend_avx512" in c["command"]
    )
    assert AVX3_NEEDS[version] <= set(avx512.split()), avx512
    pkg = stage_package(build(b), tmp_path / "pkg")
    out = tmp_path / "out"
    report = run_child([sys.executable], pkg, out, [SCENE], SIZE, cmake_env(), 300)
    info = report["build"]
    assert info["highway"] == version and info["simd_built"] == ["scalar", "avx2", "avx512"]
    assert info["simd_selected"] == info["simd_usable"][-1] and set(report["simd"]) == {info["simd_selected"]}
    assert_renders_match(out, [SCENE], SIZE, info["simd_selected"], f"Highway {version} build")
