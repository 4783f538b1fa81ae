"""Zoom videos (gbviewer.outputs.video; `gbviewer video`).

Codec tolerance: panes decoded from the MP4 are compared with the uint8 renders of the same cameras. With
libx264 at crf 0 (lossless in YUV; the loss is the RGB -> 4:2:0 YUV -> RGB round trip) on the bundled scene at
96x64 the measured error was max 5-6 and mean <= 1.3 per channel (0..255); at the default crf 18, max ~21 and mean
~2.5. The tests allow max 16 and mean 2.5 at crf 0, and check that the neighbouring frame's render is well outside
that (so the comparison would catch an off-by-one frame).
"""

from __future__ import annotations

import math
import threading

import imageio_ffmpeg
import numpy as np
import pytest

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.model.camera_paths import PathFrame, camera_path, zoom_path
from gbviewer.outputs import video
from gbviewer.outputs.figure import to_uint8, upscale_nearest

MAX_ERR, MEAN_ERR = 16, 2.5  # codec tolerance at crf 0 (see the module docstring)


def decode(path) -> tuple[dict, list[np.ndarray]]:
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return meta, [np.frombuffer(b, np.uint8).reshape(h, w, 3).copy() for b in gen]


def pane_render(bundled_scene, pf: PathFrame, settings: gb.RenderSettings) -> np.ndarray:
    rgb = to_uint8(gb.get_renderer(bundled_scene).render(pf.camera, settings).rgb)
    return rgb if rgb.shape[:2] == (pf.height, pf.width) else upscale_nearest(rgb, pf.height, pf.width)


def pane(img: np.ndarray, layout, i: int) -> np.ndarray:
    x, y = layout.origin(0, i)
    return img[y : y + layout.height, x : x + layout.width]


@pytest.mark.parametrize("kind", ["zoom", "rate"])
def test_video_frames_size_fps_and_end_frames(bundled_scene, output_view, tmp_path, kind):
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    path = camera_path(kind, output_view, 7, 1.0, 1.0 / 8.0, bundled_scene)
    seen = []
    out = tmp_path / "z.mp4"
    info = video.record_video(
        bundled_scene, path, settings, out, fps=24, crf=0, progress=lambda done, total: seen.append((done, total))
    )
    assert seen == [(i, 7) for i in range(1, 8)]
    layout = video.video_layout(path[0], len(settings))
    assert (info.width, info.height) == layout.size and info.width % 2 == 0 and info.height % 2 == 0
    n, secs = imageio_ffmpeg.count_frames_and_secs(str(out))
    meta, frames = decode(out)
    assert n == len(frames) == 7 and meta["fps"] == 24 and math.isclose(secs, 7 / 24, abs_tol=0.02)
    assert tuple(meta["size"]) == layout.size and meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    for idx, other in ((0, 1), (-1, -2)):
        for i, s in enumerate(settings):
            got = pane(frames[idx], layout, i).astype(int)
            err = np.abs(got - pane_render(bundled_scene, path[idx], s))
            assert err.max() <= MAX_ERR and err.mean() <= MEAN_ERR, (kind, idx, s.label, err.max(), err.mean())
            near = np.abs(got - pane_render(bundled_scene, path[other], s))  # the neighbouring frame fails it
            assert near.max() > MAX_ERR or near.mean() > MEAN_ERR, (near.max(), near.mean())
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left


class Boom(Exception):
    pass


@pytest.mark.parametrize("how", ["cancel", "token", "exception", "ctrl-c"])
def test_interruption_leaves_no_file(bundled_scene, output_view, tmp_path, how):
    cancel = gb.CancelToken() if how == "token" else threading.Event()

    def progress(done, total):
        if done == 2:
            if how in ("cancel", "token"):
                cancel.set()
            elif how == "exception":
                raise Boom()
            else:
                raise KeyboardInterrupt

    expected = {"exception": Boom, "ctrl-c": KeyboardInterrupt}.get(how, gb.VideoCancelled)
    with pytest.raises(expected):
        video.record_video(
            bundled_scene,
            zoom_path(output_view, 5),
            [gb.RenderSettings()],
            tmp_path / "v.mp4",
            progress=progress,
            cancel=cancel,
        )
    assert list(tmp_path.iterdir()) == []


def test_cli_video_even_size_and_refusal(tmp_path, capsys):
    out = tmp_path / "r.mp4"
    args = [
        "video",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar",
        "--path",
        "rate",
        "--size",
        "95x63",
        "--frames",
        "5",
        "--fps",
        "10",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    n, secs = imageio_ffmpeg.count_frames_and_secs(str(out))
    meta, _ = decode(out)
    assert n == 5 and math.isclose(secs, 0.5, abs_tol=0.05) and meta["fps"] == 10
    assert all(v % 2 == 0 for v in meta["size"]) and meta["size"][0] == 96  # 95 padded to even
    before = out.read_bytes()
    capsys.readouterr()
    assert main(args) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == before
    assert main(args[:-1] + [str(tmp_path / "x.gif")]) == 2  # not .mp4
    i = args.index("--frames")
    assert main(args[:i] + ["--seconds", "0.3"] + args[i + 2 :] + ["--force"]) == 0
    assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mp4"]


@pytest.mark.parametrize(
    "extra, line",
    [
        (["--path", "{tmp}"], "--path {tmp}: expected zoom, dolly, rate or a keyframes FILE.json, got a folder"),
        (
            ["--path", "{tmp}/none.json"],
            "--path {tmp}/none.json: expected zoom, dolly, rate or a keyframes FILE.json, got no such file",
        ),
        (["--inset", "1000,1000,5,5"], "--inset 1000,1000,5,5: expected a region inside the 96x64 x1 image"),
        (["--inset", "90,10,8,8"], "--inset 90,10,8,8: expected a region inside the 96x64 x1 image"),
        (["--inset=-1,0,8,8"], "--inset -1,0,8,8: expected a region inside"),
    ],
)
def test_cli_video_bad_path_or_inset_is_one_line(tmp_path, capsys, extra, line):
    """A folder as --path is not "an output inside the input"; an inset off the image is not silently dropped."""
    out = tmp_path / "v.mp4"
    args = ["video", str(gb.DEFAULT_SCENE), "--modes", "scalar", "--size", "96x64", "--frames", "2", "--out", str(out)]
    assert main(args + [a.format(tmp=tmp_path) for a in extra]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith(f"gbviewer: error: {line.format(tmp=tmp_path)}"), err
    assert not out.exists()
