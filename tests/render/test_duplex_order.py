"""The CUDA duplex canonical order without a GPU: its steps are host+device functions of gbv/order.h, so the host
compiler runs them (duplex_order_check.cpp) against the quadratic rank the kernel used before and against the
definition (each cell's visible splats stably sorted by splat_less), on random cells full of equal depths."""

from __future__ import annotations

import subprocess
from pathlib import Path

from native_builds import compile_check

REPO = Path(__file__).resolve().parents[2]


def test_linear_run_sort_equals_the_former_order(tmp_path):
    exe = tmp_path / "duplex_order_check"
    compile_check(Path(__file__).with_name("duplex_order_check.cpp"), exe, [REPO / "native" / "include"])
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    word, slots, runs = out.stdout.split()
    assert word == "ok" and int(slots) > 10_000 and int(runs) > 5_000, out.stdout  # ties were exercised
