"""Video codecs and containers (gbviewer.outputs.video.CODECS, CONTAINERS; `gbviewer video --codec`).

Each codec writes a small video that ffmpeg decodes back to the right frame count, size, codec and frames: every
decoded pane is near the render of its own camera (max 24, mean 3 per channel of 0..255 at each codec's lowest
loss: the RGB -> 4:2:0 YUV -> RGB round trip plus the codec's loss) and not near the neighbouring frame's.
"""

from __future__ import annotations

import imageio_ffmpeg
import numpy as np
import pytest

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.model.camera_paths import zoom_path
from gbviewer.outputs import video
from gbviewer.outputs.figure import to_uint8

MAX_ERR, MEAN_ERR = 24, 3.0
COMBOS = [
    ("h264", ".mp4", "h264"),
    ("h265", ".mp4", "hevc"),
    ("vp9", ".webm", "vp9"),
    ("vp9", ".mp4", "vp9"),
    ("av1", ".webm", "av1"),
    ("av1", ".mp4", "av1"),
]
BEST = {"h264": 0, "h265": 0, "vp9": 0, "av1": 1}  # each codec's lowest crf


def decode(path) -> tuple[dict, list[np.ndarray]]:
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return meta, [np.frombuffer(b, np.uint8).reshape(h, w, 3).copy() for b in gen]


@pytest.mark.parametrize("codec, ext, name", COMBOS)
def test_codec_writes_what_ffmpeg_decodes(bundled_scene, output_view, tmp_path, codec, ext, name):
    settings = [gb.RenderSettings()]
    path = zoom_path(output_view, 4, 1.0, 0.25)
    out = tmp_path / f"v{ext}"
    info = video.record_video(bundled_scene, path, settings, out, fps=12, codec=codec, crf=BEST[codec])
    meta, frames = decode(out)
    assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == len(frames) == 4
    assert tuple(meta["size"]) == (info.width, info.height) and meta["codec"] == name, meta
    layout = video.video_layout(path[0], 1)
    x, y = layout.origin(0, 0)
    renders = [to_uint8(gb.get_renderer(bundled_scene).render(pf.camera, settings[0]).rgb).astype(int) for pf in path]
    for i, frame in enumerate(frames):
        got = frame[y : y + layout.height, x : x + layout.width].astype(int)
        err = np.abs(got - renders[i])
        assert err.max() <= MAX_ERR and err.mean() <= MEAN_ERR, (codec, i, err.max(), err.mean())
        other = renders[i + 1 if i + 1 < len(renders) else i - 1]
        near = np.abs(got - other)
        assert near.max() > MAX_ERR or near.mean() > MEAN_ERR, (codec, i, near.max(), near.mean())
    assert list(tmp_path.iterdir()) == [out]


@pytest.mark.parametrize(
    "codec, out, line",
    [
        ("h264", "v.webm", "v.webm: a WEBM file cannot hold h264; use vp9, av1 or write .mp4"),
        ("h265", "v.webm", "v.webm: a WEBM file cannot hold h265; use vp9, av1 or write .mp4"),
        ("vp9", "v.gif", "v.gif: output must end in .mp4 or .webm"),
    ],
)
def test_impossible_combination_is_one_line(tmp_path, capsys, codec, out, line):
    args = [
        "video",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar",
        "--size",
        "96x64",
        "--frames",
        "2",
        "--codec",
        codec,
        "--out",
        str(tmp_path / out),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"gbviewer: error: {tmp_path / line}"], err
    assert list(tmp_path.iterdir()) == []


def test_missing_encoder_is_named(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(video, "available_encoders", lambda: frozenset({"libx264"}))
    args = [
        "video",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar",
        "--size",
        "96x64",
        "--frames",
        "2",
        "--codec",
        "av1",
        "--out",
        str(tmp_path / "v.webm"),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "codec av1" in err[0] and "no libsvtav1 or libaom-av1 encoder" in err[0], err
    with pytest.raises(gb.GBViewerError, match="crf of vp9: expected <= 63"):
        video.video_encoder("v.webm", "vp9", 64)
    with pytest.raises(gb.GBViewerError, match="crf of h264: expected <= 51"):
        video.video_encoder("v.mp4", "h264", 52)


def test_cli_codec_h265(tmp_path):
    out = tmp_path / "v.mp4"
    assert (
        main(
            [
                "video",
                str(gb.DEFAULT_SCENE),
                "--modes",
                "scalar",
                "--size",
                "96x64",
                "--frames",
                "3",
                "--codec",
                "h265",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    meta, frames = decode(out)
    assert meta["codec"] == "hevc" and len(frames) == 3
