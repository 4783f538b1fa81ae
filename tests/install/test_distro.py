"""The README's two commands, exactly as written, in a fresh Debian 13 root (scripts/check_distro.sh; slow, root and
debootstrap: CI has both): the first writes the comparison image and the zoom video, the second passes the suite
there, with Debian 13's Python 3.13, g++ 14 and Highway 1.2 and the vector path this CPU selects."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from helpers import HOST_ONLY, skip_or_fail

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.slow, HOST_ONLY]


def test_readme_commands_on_debian_13():
    if os.geteuid() != 0 or shutil.which("debootstrap") is None:
        skip_or_fail("the Debian 13 check needs root and debootstrap (apt-get install debootstrap)")
    env = {k: v for k, v in os.environ.items() if k in ("PATH", "HOME", "XDG_CACHE_HOME", "LANG")}
    proc = subprocess.run(
        ["bash", str(ROOT / "scripts" / "check_distro.sh"), "trixie"],
        capture_output=True,
        text=True,
        timeout=4500,
        env=env,
    )
    report = proc.stdout + proc.stderr
    if proc.returncode == 3:
        skip_or_fail(report.strip())
    assert proc.returncode == 0, report
    assert "wrote out/comparison.png" in report and "wrote out/zoom.mp4" in report, report
    assert re.search(r"Python 3\.13\.\d+; c\+\+ .* 14\.\d+\.\d+; Highway 1\.2\.", report), report
    assert re.search(r"check_distro: SIMD (avx2|avx512|neon) .*; the venv after the first command: ", report), report
    summary = [ln for ln in report.splitlines() if re.match(r"check_distro: \d+ passed", ln)]
    assert summary and " failed" not in summary[-1], report
