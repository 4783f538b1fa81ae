"""Zoom videos and comparison figures (gbviewer.video; `gbviewer video` and `gbviewer compare`).

Codec tolerance: panes decoded from the MP4 are compared with the uint8 renders of the same cameras. With
libx264 at crf 0 (lossless in YUV; the loss is the RGB -> 4:2:0 YUV -> RGB round trip) on the bundled scene at
96x64 the measured error was max 5-6 and mean <= 1.3 per channel (0..255); at the default crf 18, max ~21 and mean
~2.5. The tests allow max 16 and mean 2.5 at crf 0, and check that the neighbouring frame's render is well outside
that (so the comparison would catch an off-by-one frame).
"""

from __future__ import annotations

import json
import math
import threading

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

import gbviewer as gb
from gbviewer import video
from gbviewer.bench import box_downsample, psnr
from gbviewer.cli import main
from gbviewer.figure import to_uint8, upscale_nearest

W, H = 96, 64
MAX_ERR, MEAN_ERR = 16, 2.5  # codec tolerance at crf 0 (see the module docstring)


@pytest.fixture(scope="module")
def scene() -> gb.Scene:
    return gb.load(gb.DEFAULT_SCENE)


@pytest.fixture(scope="module")
def base(scene) -> gb.Camera:
    return gb.orbit_camera(scene, 30, 20, width=W, height=H)


def decode(path) -> tuple[dict, list[np.ndarray]]:
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return meta, [np.frombuffer(b, np.uint8).reshape(h, w, 3).copy() for b in gen]


def pane_render(scene, pf: video.PathFrame, settings: gb.RenderSettings) -> np.ndarray:
    rgb = to_uint8(gb.get_renderer(scene).render(pf.camera, settings).rgb)
    return rgb if rgb.shape[:2] == (pf.height, pf.width) else upscale_nearest(rgb, pf.height, pf.width)


def pane(img: np.ndarray, layout, i: int) -> np.ndarray:
    x, y = layout.origin(0, i)
    return img[y:y + layout.height, x:x + layout.width]


@pytest.mark.parametrize("kind", ["zoom", "rate"])
def test_video_frames_size_fps_and_end_frames(scene, base, tmp_path, kind):
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    path = video.camera_path(kind, base, 7, 1.0, 1.0 / 8.0, scene)
    seen = []
    out = tmp_path / "z.mp4"
    info = video.record_video(scene, path, settings, out, fps=24, crf=0,
                              progress=lambda done, total: seen.append((done, total)))
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
            err = np.abs(got - pane_render(scene, path[idx], s))
            assert err.max() <= MAX_ERR and err.mean() <= MEAN_ERR, (kind, idx, s.label, err.max(), err.mean())
            near = np.abs(got - pane_render(scene, path[other], s))  # the neighbouring frame fails it
            assert near.max() > MAX_ERR or near.mean() > MEAN_ERR, (near.max(), near.mean())
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left


def test_zoom_and_dolly_scale_the_content(scene, base):
    z = video.zoom_path(base, 5, 1.0, 1.0 / 8.0)
    assert [pf.rate for pf in z] == pytest.approx([8 ** (-i / 4) for i in range(5)], rel=1e-12)
    assert z[0].camera.fx == base.fx and np.array_equal(z[0].camera.t, base.t)
    assert math.isclose(z[-1].camera.fx, base.fx / 8) and z[-1].camera.width == W
    depth = video.scene_focus_depth(scene, base)
    d = video.dolly_path(base, 3, 1.0, 1.0 / 4.0, depth)
    p_cam = np.array([0.3, -0.2, depth])  # a point at the focus depth, in base camera coordinates
    p_world = base.R.T @ (p_cam - base.t)
    for pf in d:
        q = pf.camera.R @ p_world + pf.camera.t
        u = pf.camera.fx * q[0] / q[2] + pf.camera.cx
        assert math.isclose(u - base.cx, pf.rate * base.fx * p_cam[0] / depth, rel_tol=1e-9)
    assert z[-1].map_box((base.cx - 8, base.cy, 16, 8)) == pytest.approx((base.cx - 1, base.cy, 2, 1))
    r = video.rate_path(base, 2, 1.0, 0.25)
    assert (r[-1].camera.width, r[-1].camera.height, r[-1].width) == (24, 16, W)


def keys_for(scene) -> list[video.Keyframe]:
    cams = [gb.orbit_camera(scene, az, el, width=W, height=H) for az, el in ((0, 10), (70, 30), (150, -20), (200, 40))]
    cams[2] = cams[2].with_size(W, H)
    from dataclasses import replace
    cams[1] = replace(cams[1], fx=cams[1].fx * 1.7, fy=cams[1].fy * 1.7, cx=50.0)
    return [video.Keyframe(c, r, t) for c, r, t in zip(cams, (1.0, 0.5, 0.125, 2.0), (0.0, 0.5, 2.0, 3.0))]


def test_keyframes_pass_exactly_through_their_keys(scene):
    keys = keys_for(scene)
    at = video.interpolate_keyframes(keys, [k.time for k in keys])
    for k, g in zip(keys, at):
        for field in ("fx", "fy", "cx", "cy"):
            assert math.isclose(getattr(g.camera, field), getattr(k.camera, field), rel_tol=1e-12)
        np.testing.assert_allclose(g.camera.R, k.camera.R, atol=1e-12)
        np.testing.assert_allclose(g.camera.t, k.camera.t, atol=1e-12)
        assert math.isclose(g.rate, k.rate, rel_tol=1e-12) and g.time == k.time
    # between keys: a proper rotation, continuous, rates inside the keys' range (monotone, no overshoot)
    ts = np.linspace(0, 3, 301)
    path = video.interpolate_keyframes(keys, ts)
    for a, b in zip(path, path[1:]):
        assert np.abs(a.camera.R @ a.camera.R.T - np.eye(3)).max() < 1e-9
        assert np.abs(a.camera.R - b.camera.R).max() < 0.05 and np.linalg.norm(a.camera.position
                                                                                - b.camera.position) < 0.1
    rates = np.array([p.rate for p in path])
    assert rates.min() >= 0.125 - 1e-12 and rates.max() <= 2.0 + 1e-12
    # a keyframe path whose frames fall on the key times renders the keys' cameras
    frames = video.keyframe_path(keys, 7)  # frames every 0.5 s: keys at frames 0, 1, 4, 6
    for i, k in zip((0, 1, 4, 6), keys):
        want = k.camera.at_sampling_rate(k.rate)
        assert (frames[i].camera.width, frames[i].camera.height) == (want.width, want.height)
        np.testing.assert_allclose(frames[i].camera.R, want.R, atol=1e-12)
        assert frames[i].rate == pytest.approx(k.rate, rel=1e-12) and (frames[i].width, frames[i].height) == (W, H)


def test_two_keys_slerp_the_rotation(base):
    from dataclasses import replace

    def rot_y(deg):
        a = math.radians(deg)
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    k0 = video.Keyframe(replace(base, R=np.eye(3), t=np.zeros(3)))
    k1 = video.Keyframe(replace(base, R=rot_y(90), t=np.zeros(3)))
    mid = video.interpolate_keyframes([k0, k1], [0.25, 0.5])
    np.testing.assert_allclose(mid[0].camera.R, rot_y(22.5), atol=1e-12)
    np.testing.assert_allclose(mid[1].camera.R, rot_y(45), atol=1e-12)


def test_keyframes_json_forms_and_round_trip(scene, base, tmp_path):
    doc = {"keyframes": [
        {"time": 0, "orbit": [30, 20, 0]},
        {"time": 1, "position": [0.5, -0.5, 2.0], "look_at": [0, 0, 0], "rate": "1/4", "fov_y_deg": 40},
        {"time": 2, "R": np.eye(3).tolist(), "t": [0, 0, 3], "rate": 0.5},
        {"time": 3, "rotation": np.eye(3).tolist(), "position": [0, 0, -4]},
    ]}
    f = tmp_path / "keys.json"
    f.write_text(json.dumps(doc))
    keys = video.load_keyframes(f, base, scene)
    assert [k.rate for k in keys] == [1.0, 0.25, 0.5, 1.0]
    np.testing.assert_allclose(keys[0].camera.R, base.R, atol=1e-12)  # base is the same orbit
    np.testing.assert_allclose(keys[3].camera.t, [0, 0, 4])
    assert math.isclose(keys[1].camera.fy, 0.5 * H / math.tan(math.radians(20)))
    g = tmp_path / "again.json"
    g.write_text(json.dumps(video.keyframes_to_json(keys)))
    again = video.load_keyframes(g, base, scene)
    for a, b in zip(keys, again):
        np.testing.assert_array_equal(a.camera.R, b.camera.R)
        assert (a.camera.fx, a.rate, a.time) == (b.camera.fx, b.rate, b.time)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"time": 1, "orbit": [0, 0, 0]}, {"time": 0, "orbit": [9, 0, 0]}]))
    with pytest.raises(gb.GBViewerError, match="increasing"):
        video.load_keyframes(bad, base, scene)


class Boom(Exception):
    pass


@pytest.mark.parametrize("how", ["cancel", "exception", "ctrl-c"])
def test_interruption_leaves_no_file(scene, base, tmp_path, how):
    cancel = threading.Event()

    def progress(done, total):
        if done == 2:
            if how == "cancel":
                cancel.set()
            elif how == "exception":
                raise Boom()
            else:
                raise KeyboardInterrupt

    expected = {"cancel": video.Cancelled, "exception": Boom, "ctrl-c": KeyboardInterrupt}[how]
    with pytest.raises(expected):
        video.record_video(scene, video.zoom_path(base, 5), [gb.RenderSettings()], tmp_path / "v.mp4",
                           progress=progress, cancel=cancel)
    assert list(tmp_path.iterdir()) == []


def test_cli_video_even_size_and_refusal(tmp_path, capsys):
    out = tmp_path / "r.mp4"
    args = ["video", str(gb.DEFAULT_SCENE), "--modes", "scalar", "--path", "rate", "--size", "95x63", "--frames",
            "5", "--fps", "10", "--out", str(out)]
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
    assert main(args[:i] + ["--seconds", "0.3"] + args[i + 2:] + ["--force"]) == 0
    assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mp4"]


def test_compare_cells_equal_the_renders(scene, base):
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    rates = [2.0, 1.0, 0.5, 0.25]
    cmp = video.compare_figure(scene, base, settings, rates)
    img = np.asarray(cmp.image)
    cap = cmp.layout.caption_height
    assert cap > 0 and img.shape[:2] == (4 * (H + cap) + 3 * 4, 2 * W + 4)
    ref = gb.render(scene, base, "scalar").rgb
    for r, rate in enumerate(rates):
        for c, s in enumerate(settings):
            rgb = gb.get_renderer(scene).render(base.at_sampling_rate(rate), s).rgb
            x, y = cmp.layout.origin(r, c)
            np.testing.assert_array_equal(img[y:y + H, x:x + W], upscale_nearest(to_uint8(rgb), H, W))
            p = cmp.psnr[r][c]
            if rate > 1:
                assert p is None
            elif rate == 1 and s.mode == gb.Mode.SCALAR:
                assert p == math.inf
            else:
                assert p == pytest.approx(psnr(rgb, box_downsample(ref, round(1 / rate))))


def test_cli_compare_with_inset_and_refusal(tmp_path, base, scene, capsys):
    out = tmp_path / "fig.png"
    args = ["compare", str(gb.DEFAULT_SCENE), "--modes", "gaussian_blending", "--rates", "1,1/4", "--width", str(W),
            "--height", str(H), "--orbit", "30,20,0", "--inset", "10,10,16,12", "--out", str(out)]
    assert main(args) == 0
    assert "PSNR" in capsys.readouterr().out
    img = np.asarray(Image.open(out).convert("RGB"))
    cmp_layout = video.compare_figure(scene, base, [gb.RenderSettings(gb.Mode.GAUSSIAN_BLENDING)], [1.0]).layout
    cap = cmp_layout.caption_height
    assert img.shape[:2] == (2 * (H + cap) + 4, W)
    for r, rate in enumerate((1.0, 0.25)):
        rgb = gb.render(scene, base.at_sampling_rate(rate), "gaussian_blending").rgb
        y = r * (H + cap + 4)
        # rows between the region's outline (y <= 22) and the magnified inset (bottom-right, from y = 41)
        np.testing.assert_array_equal(img[y + 24:y + 40], upscale_nearest(to_uint8(rgb), H, W)[24:40])
        assert not np.array_equal(img[y + 41:y + H], upscale_nearest(to_uint8(rgb), H, W)[41:])  # inset drawn
    before = out.read_bytes()
    assert main(args) == 2 and out.read_bytes() == before
    assert "--force" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]
