"""`gbviewer trace`: tables per mode on stdout, every trace as JSON (never overwriting without --force), and a pixel
outside the image as one error line with exit status 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import gbviewer as gb

ENV = dict(os.environ, PYTHONPATH=str(Path(gb.__file__).resolve().parents[1]))  # the gbviewer under test
VIEW = ["--orbit", "30,20,0", "--width", "320", "--height", "240", "--scale", "1/8"]  # 40x30 pixels


def run(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gbviewer", "trace", str(gb.DEFAULT_SCENE), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=ENV,
        timeout=300,
    )


def test_tables_and_json(tmp_path, bundled_scene):
    out = run(
        *VIEW,
        "--pixel",
        "20,15",
        "--modes",
        "scalar,gaussian_blending:2",
        "--top",
        "3",
        "--json",
        "t.json",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert "scalar: pixel (20, 15) of 40x30" in out.stdout
    assert "gaussian_blending 2x2: pixel (20, 15) of 40x30" in out.stdout
    assert "window centre" in out.stdout and "rejected: " in out.stdout and "Pixel per mode" in out.stdout
    assert out.stdout.rstrip().endswith("t.json")
    doc = json.loads((tmp_path / "t.json").read_text())
    assert doc["scene"] == str(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=320, height=240).at_sampling_rate(1 / 8)
    for trace, (mode, n) in zip(doc["traces"], [("scalar", 1), ("gaussian_blending", 2)]):
        assert (trace["x"], trace["y"], trace["supersample"]) == (20, 15, n)
        assert len(trace["samples"]) == n * n and all(s["steps"] for s in trace["samples"])
        rgb = gb.render(bundled_scene, cam, mode, n).rgb[15, 20]
        np.testing.assert_allclose(trace["color"], rgb, atol=1e-5)
        assert trace == json.loads(gb.trace_pixel(bundled_scene, cam, 20, 15, mode, n).to_json())
    shown = [line for line in out.stdout.splitlines() if line.startswith("│")]
    assert len(shown) == 3 + 3 + 2  # --top 3 rows per mode, then one summary row per mode

    again = run(*VIEW, "--pixel", "20,15", "--json", "t.json", cwd=tmp_path)
    assert again.returncode == 2 and "exists; pass --force" in again.stderr
    assert json.loads((tmp_path / "t.json").read_text()) == doc
    forced = run(
        *VIEW, "--pixel", "3,4", "--modes", "wsr", "--supersample", "3", "--json", "t.json", "--force", cwd=tmp_path
    )
    assert forced.returncode == 0, forced.stderr
    (trace,) = json.loads((tmp_path / "t.json").read_text())["traces"]
    assert (trace["mode"], trace["x"], trace["y"]) == ("wsr 3x3", 3, 4)


def test_pixel_outside_the_image_is_one_line_exit_2(tmp_path):
    out = run(*VIEW, "--pixel", "40,3", "--json", "t.json", cwd=tmp_path)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.splitlines() == [
        "gbviewer: error: --pixel 40,3: outside the 40x30 image at --scale 0.125 (x in 0..39, y in 0..29)"
    ]
    assert not (tmp_path / "t.json").exists()
    bad = run(*VIEW, "--pixel=-1,3", cwd=tmp_path)
    assert bad.returncode == 2 and len(bad.stderr.splitlines()) == 1 and "argument --pixel: X" in bad.stderr
