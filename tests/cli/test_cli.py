"""The command line: info, render, demo; clear errors with exit status 2 and no traceback."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import patch_commands
from PIL import Image

import gbviewer as gb
from gbviewer import cli
from gbviewer.cli import main
from gbviewer.core.files import check_writable

GBVIEWER = [sys.executable, "-m", "gbviewer"]
ENV = dict(os.environ, PYTHONPATH=str(Path(gb.__file__).resolve().parents[1]))  # the gbviewer under test


def run(*args: str, cwd) -> subprocess.CompletedProcess:
    """Run `python -m gbviewer` in a subprocess, with the package under test."""
    return subprocess.run([*GBVIEWER, *args], capture_output=True, text=True, cwd=cwd, env=ENV, timeout=120)


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
    # a picture-making command draws gaussian_blending's fast kernel unless the spec says +exact (the library: exact)
    np.testing.assert_array_equal(arr, gb.render(scene, cam, "gaussian_blending+fast", backend="auto").rgb)
    exact = tmp_path / "exact.npy"
    assert main(["render", *common, "--mode", "gaussian_blending+exact", "--scale", "1/2", "--out", str(exact)]) == 0
    np.testing.assert_array_equal(np.load(exact), gb.render(scene, cam, "gaussian_blending", backend="auto").rgb)
    assert not np.array_equal(np.load(exact), arr)
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_render_orthographic(tmp_path):
    """--projection orthographic: an orbit at the same eye with f / distance pixels per unit (a non-empty image, the
    library's render); a training camera converted at the depth of the scene's centre; bad values: exit 2, one line."""
    npy = tmp_path / "o.npy"
    common = [str(gb.DEFAULT_SCENE), "--width", "64", "--height", "48", "--orbit", "10,20,0"]
    assert main(["render", *common, "--projection", "orthographic", "--out", str(npy)]) == 0
    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 10, 20, width=64, height=48, projection="orthographic")
    arr = np.load(npy)
    assert (arr.max(axis=2) > 0.1).mean() > 0.2
    np.testing.assert_array_equal(arr, gb.render(scene, cam).rgb)
    cams = tmp_path / "cameras.json"
    cams.write_text(
        json.dumps(
            [
                {
                    "width": 64,
                    "height": 48,
                    "fx": cam.fx,
                    "fy": cam.fy,
                    "projection": "orthographic",
                    "position": cam.position.tolist(),
                    "rotation": cam.R.T.tolist(),
                }
            ]
        )
    )
    persp = tmp_path / "p.npy"
    assert (
        main(
            [
                "render",
                str(gb.DEFAULT_SCENE),
                "--cameras",
                str(cams),
                "--projection",
                "perspective",
                "--out",
                str(persp),
            ]
        )
        == 0
    )
    assert (np.load(persp).max(axis=2) > 0.1).mean() > 0.2
    proc = run("render", str(gb.DEFAULT_SCENE), "--projection", "fisheye", "--out", "x.png", cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1
    assert "--projection: invalid choice: 'fisheye'" in proc.stderr and not (tmp_path / "x.png").exists()


def test_backend_defaults_to_auto_and_says_its_choice_once(tmp_path):
    """--backend auto (the default) renders on choose_backend()'s pick and says it on stderr, in one line; an
    explicit backend says nothing."""
    picked = gb.choose_backend()
    common = [str(gb.DEFAULT_SCENE), "--width", "32", "--height", "24", "--out"]
    proc = run("render", *common, "a.png", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr == f"gbviewer: backend {picked}\n"
    assert f"on {picked.name}:" in proc.stdout
    proc = run("render", *common, "b.png", "--backend", "cpu", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr == "" and "on cpu:" in proc.stdout
    parser = cli.build_parser()
    for command in ("render", "demo", "video", "compare", "view"):
        args = parser.parse_args([command, "s.ply", "--out", "x"] if command != "demo" else [command])
        assert args.backend == (None if command == "view" else "auto")  # view: the viewer's saved choice
        assert parser.parse_args([*([command, "s.ply", "--out", "x"]), "--backend", "glsl"]).backend == "glsl"


def test_view_passes_an_explicit_backend_to_the_viewer(monkeypatch):
    opened = []
    monkeypatch.setattr(
        "gbviewer.app.open_window", lambda scene, cameras, backend=None, **_: opened.append(backend) or (True, "")
    )
    assert main([str(gb.DEFAULT_SCENE), "--backend", "cpu"]) == 0 and main([]) == 0
    assert opened == ["cpu", None]


def test_render_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "x.png"
    out.write_bytes(b"precious")
    args = ["render", str(gb.DEFAULT_SCENE), "--width", "32", "--height", "32", "--out", str(out)]
    assert main(args) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"precious"
    assert main(args + ["--force"]) == 0
    assert Image.open(out).size == (32, 32)


@pytest.mark.parametrize(
    "args, message",
    [
        (["render", "missing.ply", "--out", "x.png"], "no such file"),
        (["render", "{scene}", "--scale", "0", "--out", "x.png"], "sampling rate"),
        (["render", "{scene}", "--out", "x.jpg"], ".png or .npy"),
        (["render", "{scene}", "--cameras", "{bad}", "--out", "x.png"], "cameras.json"),
        (["info", "{bad}"], "cameras.json"),
    ],
)
def test_bad_input_one_line_exit_2(tmp_path, args, message):
    bad = tmp_path / "cameras.json"
    bad.write_text("{not json")
    args = [a.format(scene=gb.DEFAULT_SCENE, bad=bad) for a in args]
    proc = run(*args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.splitlines()) == 1


def test_a_file_name_with_control_characters_stays_one_line(tmp_path):
    """A scene named with a newline (or a terminal escape) split the error over two lines (or drove the terminal):
    control characters are written as escapes."""
    bad = tmp_path / "a\nb\x1b[2J.ply"
    bad.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nend_header\n")
    proc = run("info", str(bad), cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1
    assert "a\\nb\\x1b[2J.ply" in proc.stderr and "\x1b" not in proc.stderr


def test_demo_writes_comparison_and_zoom_video(tmp_path):
    import imageio_ffmpeg

    from gbviewer.cli.view import DEMO_VIDEO_FRAMES

    proc = run("demo", "--width", "96", "--height", "64", "--out", "out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    img = Image.open(tmp_path / "out" / "comparison.png")
    assert img.size == (3 * 96 + 2 * 4, 2 * 64 + 4)
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "out" / "zoom.mp4"))
    assert frames == DEMO_VIDEO_FRAMES
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["comparison.png", "zoom.mp4"]


def test_argparse_errors_are_one_line_with_a_hint(tmp_path):
    proc = run("video", str(gb.DEFAULT_SCENE), "--fps", "inf", "--out", "v.mp4", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == (
        "gbviewer video: error: argument --fps: expected a finite number, got 'inf' (see gbviewer video --help)\n"
    )
    proc = run("render", "--mode", "nope", cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1 and "usage" not in proc.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_during_video_leaves_no_temporary(tmp_path, sig):
    """SIGTERM and SIGHUP clean up like Ctrl-C: ffmpeg stopped, the hidden temporary removed, exit 128 + N."""
    proc = subprocess.Popen(
        [
            *GBVIEWER,
            "video",
            str(gb.DEFAULT_SCENE),
            "--modes",
            "scalar",
            "--size",
            "32x24",
            "--frames",
            "100000",
            "--out",
            "zoom.mp4",
        ],
        cwd=tmp_path,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob(".zoom-*")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(tmp_path.glob(".zoom-*")), "the video never started"
        time.sleep(0.5)  # frames in flight
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + sig
    assert err.splitlines()[-1] == f"gbviewer: interrupted ({sig.name})" and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_closed_stdout_exits_quietly(tmp_path):
    """`gbviewer info scene.ply | head -0`: the reader is gone before anything is written."""
    proc = subprocess.Popen(
        [*GBVIEWER, "info", str(gb.DEFAULT_SCENE)],
        cwd=tmp_path,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 128 + signal.SIGPIPE and err == ""


def test_check_writable(tmp_path):
    (tmp_path / "file").write_text("x")
    assert check_writable(tmp_path / "new" / "deeper" / "a.json") == tmp_path / "new" / "deeper" / "a.json"
    assert check_writable(tmp_path / "file", force=True) and check_writable(tmp_path, folder=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # creates nothing
    for path, kwargs, message in [
        (tmp_path / "file", {}, "exists; pass --force"),
        (tmp_path, {}, "is a folder"),
        (tmp_path / "file", {"folder": True}, "not a folder"),
        (tmp_path / "file" / "a.json", {}, "file is not a folder"),
    ]:
        with pytest.raises(gb.GBViewerError, match=message):
            check_writable(path, **kwargs)


def test_check_writable_where_nothing_can_be_written():
    """/proc takes no new files, for root either (a permission bit would not stop root, who runs CI)."""
    with pytest.raises(gb.GBViewerError, match="^/proc/gbviewer/a.png: cannot write in /proc "):
        check_writable(Path("/proc/gbviewer/a.png"))


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "{scene}", "--json", "{file}/b.json"],
        ["bench", "{scene}", "--plots", "{file}"],
        ["bench", "{scene}", "--plots", "{plots}"],
        ["video", "{scene}", "--out", "{file}/v.mp4"],
        ["render", "{scene}", "--out", "{file}/a.png"],
        ["compare", "{scene}", "--out", "{file}"],
        ["convert", "{scene}", "{file}/a.ply"],
        ["demo", "--out", "{file}"],
    ],
)
def test_unwritable_outputs_fail_before_the_work(argv, tmp_path, capsys, monkeypatch):
    """An output that cannot be written is refused before any scene is loaded (not after the whole benchmark)."""
    file, plots = tmp_path / "file", tmp_path / "plots"
    file.write_text("x")
    plots.mkdir()
    (plots / (gb.DEFAULT_SCENE.stem + ".png")).write_text("old plot")
    patch_commands(monkeypatch, "load", lambda *a: pytest.fail("loaded a scene"))
    monkeypatch.setattr("gbviewer.bench.run.load", lambda *a: pytest.fail("benchmarked"))
    argv = [a.format(scene=gb.DEFAULT_SCENE, file=file, plots=plots) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and str(tmp_path) in err
    assert file.read_text() == "x" and sorted(p.name for p in tmp_path.iterdir()) == ["file", "plots"]


@pytest.mark.parametrize(
    "length",
    [
        ["--seconds", "1e9"],
        ["--fps", "1000", "--seconds", "1000"],
        ["--frames", "6", "--max-frames", "5"],
        ["--path", "{keys}"],
    ],
)
def test_video_length_is_bounded_before_any_frame(length, tmp_path, capsys, monkeypatch):
    keys = tmp_path / "keys.json"
    keys.write_text(json.dumps([{"orbit": [0, 20, 0], "time": 0}, {"orbit": [90, 20, 0], "time": 1e9}]))
    monkeypatch.setattr("gbviewer.outputs.video.get_renderer", lambda *a: pytest.fail("rendered"))
    argv = ["video", str(gb.DEFAULT_SCENE), "--out", str(tmp_path / "v.mp4"), *(a.format(keys=keys) for a in length)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("gbviewer: error: frames of the video (at most ") and "--max-frames raises the limit" in err
    assert len(err.splitlines()) == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["keys.json"]
