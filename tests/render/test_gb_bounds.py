"""gaussian_blending's lane-group box (blend_tile.h, gaussian_blending_bounds) is conservative, without a render: the
host compiler runs gb_bounds_check.cpp, which places random windows around random splats (needle-thin ones and
opacities just above 1/256 included) and checks that every window the float blend step changes, and every window whose
float64 window-integrated alpha reaches 1/256, has its centre inside the box grown by its half perimeter."""

from __future__ import annotations

import subprocess
from pathlib import Path

from native_builds import compile_check

REPO = Path(__file__).resolve().parents[2]


def test_window_cutoff_box_holds_every_visible_window(tmp_path):
    exe = tmp_path / "gb_bounds_check"
    includes = [REPO / "native" / "include", REPO / "native" / "cpu"]
    compile_check(Path(__file__).with_name("gb_bounds_check.cpp"), exe, includes)
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    word, windows, taken, edge, tighter = out.stdout.split()
    # the windows reached the splats, many of them at the box's edge, and most boxes were tighter than the radius
    assert word == "ok" and int(windows) == 2_000_000 and int(taken) > 100_000 and int(edge) > 5_000, out.stdout
    assert int(tighter) > 2_000, out.stdout
