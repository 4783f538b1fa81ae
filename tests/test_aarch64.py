"""The aarch64 build (issue 26), cross-built here and run under qemu-aarch64 with an aarch64 Python
(scripts/check_aarch64.sh; slow, CI runs it): NEON built and selected, and renders of two shared scenes in five modes
equal to x86-64's (this process's scalar path, the reference every vector path is held to) within the tolerance of
native_builds.py. Skips, saying why, only where the cross tools or the aarch64 Python are missing (CI installs them:
scripts/setup.sh as root, and this test runs the script with --install as root)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import shared_scene, skip_or_fail
from native_builds import ROOT, assert_renders_match, run_child

SCENES = ("plant.splat", "biker.compressed.ply")
SIZE = 64  # under emulation a render is 10-300x slower (analytic the most): the ten renders take ~50 s


@pytest.mark.slow
@pytest.mark.skipif(platform.machine() != "x86_64", reason="cross-built from x86-64")
def test_aarch64_build_runs_neon_and_renders_as_x86(tmp_path):
    scenes = [shared_scene(name) for name in SCENES]
    build = tmp_path / "aarch64"
    install = ["--install"] if os.geteuid() == 0 else []
    proc = subprocess.run(["bash", str(ROOT / "scripts" / "check_aarch64.sh"), *install, str(build)],
                          capture_output=True, text=True, timeout=900, env={**os.environ, "PYTHON": sys.executable},
                          cwd=ROOT)
    if proc.returncode == 3:
        skip_or_fail(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert proc.stdout.strip().splitlines()[-1].startswith("aarch64 SIMD neon (built: scalar, neon")
    rootfs = Path(os.environ.get("GBVIEWER_AARCH64_ROOT")
                  or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gbviewer" / "aarch64-root")
    python = ["qemu-aarch64", "-L", str(rootfs), str(rootfs / "usr" / "bin" / "python3")]
    report = run_child(python, build / "pkg", tmp_path / "out", scenes, SIZE, {"PATH": "/usr/bin:/bin"}, 600)
    info = report["build"]
    assert info["simd_built"] == info["simd_usable"] == ["scalar", "neon"] and info["simd_selected"] == "neon"
    assert set(report["simd"]) == {"neon"} and info["compiler"].startswith("GNU")
    assert_renders_match(tmp_path / "out", scenes, SIZE, "scalar", "aarch64 neon vs x86-64 scalar")
