"""The aarch64 build (docs/install.md#aarch64), cross-built here and run under qemu-aarch64 with an aarch64 Python
(scripts/check_aarch64.sh; slow, CI runs it): NEON built and selected; renders of two shared scenes in five modes
equal to x86-64's (this process's scalar path, the reference every vector path is held to) within the tolerance of
native_builds.py; and test_simd*.py's NEON tests (NEON against the scalar path of the same aarch64 module, the
preprocess bit for bit) pass under emulation. Skips, saying why, only where the cross tools or the aarch64 Python are
missing (CI installs them: scripts/setup.sh as root, and this test runs the script with --install as root)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import HOST_ONLY, shared_scene, skip_or_fail
from native_builds import ROOT, assert_renders_match, run_child

SCENES = ("plant.splat", "biker.compressed.ply")
SIZE = 96  # under emulation a render is 10-50x slower than native
ROOTFS = Path(
    os.environ.get("GBVIEWER_AARCH64_ROOT")
    or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gbviewer" / "aarch64-root"
)
PYTHON = ["qemu-aarch64", "-L", str(ROOTFS), str(ROOTFS / "usr" / "bin" / "python3")]
ENV = {"PATH": "/usr/bin:/bin"}  # nothing of this process's environment selects code paths in the emulated one

pytestmark = [
    pytest.mark.slow,
    HOST_ONLY,
    pytest.mark.skipif(platform.machine() != "x86_64", reason="cross-built from x86-64"),
]


@pytest.fixture(scope="module")
def aarch64_pkg(tmp_path_factory) -> Path:
    """The cross-built module staged beside a copy of the package (scripts/check_aarch64.sh), its SIMD line checked."""
    build = tmp_path_factory.mktemp("aarch64") / "b"
    install = ["--install"] if os.geteuid() == 0 else []
    proc = subprocess.run(
        ["bash", str(ROOT / "scripts" / "check_aarch64.sh"), *install, str(build)],
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "PYTHON": sys.executable},
        cwd=ROOT,
    )
    if proc.returncode == 3:
        skip_or_fail(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert proc.stdout.strip().splitlines()[-1].startswith("aarch64 SIMD neon (built: scalar, neon")
    return build / "pkg"


def test_aarch64_build_runs_neon_and_renders_as_x86(aarch64_pkg, tmp_path):
    scenes = [shared_scene(name) for name in SCENES]
    report = run_child(PYTHON, aarch64_pkg, tmp_path / "out", scenes, SIZE, ENV, 600)
    info = report["build"]
    assert info["simd_built"] == info["simd_usable"] == ["scalar", "neon"] and info["simd_selected"] == "neon"
    assert set(report["simd"]) == {"neon"} and info["compiler"].startswith("GNU")
    assert_renders_match(tmp_path / "out", scenes, SIZE, "scalar", "aarch64 neon vs x86-64 scalar")


def test_simd_tests_pass_on_neon_under_emulation(aarch64_pkg):
    """test_simd.py and test_simd_preprocess.py -k neon in the aarch64 Python (their 48 NEON tests, ~90 s here)."""
    tests = [str(aarch64_pkg / "tests" / "render" / name) for name in ("test_simd.py", "test_simd_preprocess.py")]
    proc = subprocess.run(
        [*PYTHON, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests, "-k", "neon"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd="/",
        env={**ENV, "PYTHONPATH": str(aarch64_pkg)},
    )
    summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else proc.stderr[-2000:]
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert " passed" in summary and "skipped" not in summary and "error" not in summary, summary
