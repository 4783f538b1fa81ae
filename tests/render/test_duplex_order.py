"""The CUDA duplex canonical order without a GPU: its steps are host+device functions of gbv/order.h, so the host
compiler runs them (duplex_order_check.cpp) against the quadratic rank the kernel used before and against the
definition (each cell's visible splats stably sorted by splat_less), on random cells full of equal depths."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CXX = shutil.which("c++") or shutil.which("g++")


@pytest.mark.skipif(CXX is None, reason="no C++ compiler on PATH")
def test_linear_run_sort_equals_the_former_order(tmp_path):
    exe = tmp_path / "duplex_order_check"
    subprocess.run(
        [
            CXX,
            "-std=c++17",
            "-O1",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-I",
            str(REPO / "native" / "include"),
            str(Path(__file__).with_name("duplex_order_check.cpp")),
            "-o",
            str(exe),
        ],
        check=True,
        timeout=120,
    )
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    word, slots, runs = out.stdout.split()
    assert word == "ok" and int(slots) > 10_000 and int(runs) > 5_000, out.stdout  # ties were exercised
