"""The command line: info, render, demo; clear errors with exit status 2 and no traceback."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import gbviewer as gb
from gbviewer.cli import main


def run(*args: str, cwd) -> subprocess.CompletedProcess:
    """Run `python -m gbviewer` outside the source tree (so the installed package with its native module is used)."""
    return subprocess.run([sys.executable, "-m", "gbviewer", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=120)


def test_info_json(capsys):
    assert main(["info", str(gb.DEFAULT_SCENE), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["splats"] == 4721 and info["sh_degree"] == 3 and info["filter_3D"] is False
    assert info["format"] == "inria-ply" and "transform" in info["properties"]


def test_render_png_and_npy(tmp_path):
    png, npy = tmp_path / "a.png", tmp_path / "a.npy"
    common = [str(gb.DEFAULT_SCENE), "--width", "64", "--height", "48", "--orbit", "10,20,0"]
    assert main(["render", *common, "--mode", "gaussian_blending", "--out", str(png)]) == 0
    assert Image.open(png).size == (64, 48)
    assert main(["render", *common, "--mode", "gaussian_blending", "--scale", "1/2", "--out", str(npy)]) == 0
    arr = np.load(npy)
    assert arr.shape == (24, 32, 3) and arr.dtype == np.float32
    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 10, 20, width=64, height=48).at_sampling_rate(0.5)
    np.testing.assert_array_equal(arr, gb.render(scene, cam, "gaussian_blending").rgb)
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_render_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "x.png"
    out.write_bytes(b"precious")
    args = ["render", str(gb.DEFAULT_SCENE), "--width", "32", "--height", "32", "--out", str(out)]
    assert main(args) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"precious"
    assert main(args + ["--force"]) == 0
    assert Image.open(out).size == (32, 32)


@pytest.mark.parametrize("args, message", [
    (["render", "missing.ply", "--out", "x.png"], "no such file"),
    (["render", "{scene}", "--scale", "0", "--out", "x.png"], "sampling rate"),
    (["render", "{scene}", "--out", "x.jpg"], ".png or .npy"),
    (["render", "{scene}", "--cameras", "{bad}", "--out", "x.png"], "cameras.json"),
    (["info", "{bad}"], "cameras.json"),
])
def test_bad_input_one_line_exit_2(tmp_path, args, message):
    bad = tmp_path / "cameras.json"
    bad.write_text("{not json")
    args = [a.format(scene=gb.DEFAULT_SCENE, bad=bad) for a in args]
    proc = run(*args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 or "usage:" in proc.stderr


def test_demo_writes_comparison_and_zoom_video(tmp_path):
    import imageio_ffmpeg

    from gbviewer.cli import DEMO_VIDEO_FRAMES

    proc = run("demo", "--width", "96", "--height", "64", "--out", "out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    img = Image.open(tmp_path / "out" / "comparison.png")
    assert img.size == (3 * 96 + 2 * 4, 2 * 64 + 4)
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "out" / "zoom.mp4"))
    assert frames == DEMO_VIDEO_FRAMES
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["comparison.png", "zoom.mp4"]
