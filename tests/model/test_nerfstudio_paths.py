"""nerfstudio's camera_path.json (gbviewer.model.nerfstudio_paths; `gbviewer video --camera-path`).

The files here are written as nerfstudio's viewer writes them (nerfstudio-project/nerfstudio:
nerfstudio/viewer/render_panel.py `_write_json`): OpenGL camera-to-world matrices built by hand from an eye, a
target and an up vector (three.js's lookAt: the camera's +z points from the target to the eye, x = up x z), so the
axes conversion is checked against an independent construction, not against its own inverse.
"""

from __future__ import annotations

import json
import math

import imageio_ffmpeg
import numpy as np
import pytest
from helpers import OUTPUT_H as H
from helpers import OUTPUT_W as W

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.core.errors import InvalidValue
from gbviewer.model.camera import camera_key
from gbviewer.model.camera_paths import nerfstudio_frames
from gbviewer.model.keyframes import Keyframe
from gbviewer.model.nerfstudio_paths import (
    load_nerfstudio_path,
    nerfstudio_json,
    path_from_keyframes,
    save_nerfstudio_path,
)

UP = np.array([0.0, 0.0, 1.0])


def gl_look_at(eye, target, up=UP) -> list[float]:
    """A flattened OpenGL camera-to-world matrix (three.js Matrix4.lookAt convention)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (eye - target) / np.linalg.norm(eye - target)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, eye
    return m.ravel().tolist()


def centre_and_eyes(scene, n):
    lo, hi = scene.robust_bounds()
    c = (np.asarray(lo, float) + hi) / 2
    r = float(np.linalg.norm(np.asarray(hi, float) - lo))
    return c, [c + r * np.array([math.cos(a), math.sin(a), 0.35]) for a in np.linspace(0.3, 1.1, n)]


def nerfstudio_doc(scene, frames=6, fps=24.0, seconds=0.25) -> dict:
    """A camera_path.json in the layout nerfstudio's viewer writes (three keyframes, `frames` path entries)."""
    c, eyes = centre_and_eyes(scene, 3)
    _, path_eyes = centre_and_eyes(scene, frames)
    return {
        "default_fov": 50.0,
        "default_transition_sec": 0.1,
        "keyframes": [
            {
                "matrix": gl_look_at(e, c),
                "fov": 50.0 + 5 * i,
                "aspect": W / H,
                "override_transition_enabled": i == 2,
                "override_transition_sec": 0.15 if i == 2 else None,
            }
            for i, e in enumerate(eyes)
        ],
        "camera_type": "perspective",
        "render_height": float(H),
        "render_width": float(W),
        "fps": fps,
        "seconds": seconds,
        "is_cycle": False,
        "smoothness_value": 0.0,
        "camera_path": [
            {"camera_to_world": gl_look_at(e, c), "fov": 50.0 + i, "aspect": W / H} for i, e in enumerate(path_eyes)
        ],
    }


def assert_docs_equal(a: dict, b: dict) -> None:
    """Equal key by key; numbers within float32 rounding (the cameras hold float32 poses)."""
    assert a.keys() == b.keys(), (a.keys(), b.keys())
    for k in a:
        if isinstance(a[k], list):
            assert len(a[k]) == len(b[k]), k
            for x, y in zip(a[k], b[k]):
                assert_docs_equal(x, y) if isinstance(x, dict) else np.testing.assert_allclose(x, y, atol=2e-5)
        elif isinstance(a[k], (int, float)) and not isinstance(a[k], bool):
            assert math.isclose(a[k], b[k], rel_tol=1e-6, abs_tol=1e-6), (k, a[k], b[k])
        else:
            assert a[k] == b[k], (k, a[k], b[k])


def test_nerfstudio_file_round_trips(bundled_scene, tmp_path):
    doc = nerfstudio_doc(bundled_scene)
    src = tmp_path / "camera_path.json"
    src.write_text(json.dumps(doc))
    p = load_nerfstudio_path(src)
    assert p.size == (W, H) and len(p.frames) == 6 and len(p.keys) == 3
    assert [k.time for k in p.keys] == pytest.approx([0.0, 0.1, 0.25])  # default, then key 2's override
    assert p.frame_rate == 6 / 0.25  # ns-render: len(camera_path) / seconds
    out = save_nerfstudio_path(p, tmp_path / "again.json")
    again = json.loads(out.read_text())
    expected = dict(doc, render_width=W, render_height=H, default_fov=50.0)
    assert_docs_equal(again, expected)
    assert_docs_equal(nerfstudio_json(load_nerfstudio_path(out)), again)  # imported then exported: itself


def test_keyframes_exported_and_imported_are_themselves(tmp_path):
    keys = [
        Keyframe(gb.Camera.look_at(e, [0, 0, 0], [0, 0, 1], W, H, fov), 1.0, t)
        for e, fov, t in (([3, 0, 1], 40, 0.0), ([0, 3, 1], 50, 0.5), ([-3, 0, 1], 60, 1.25))
    ]
    p = path_from_keyframes(keys, fps=8)
    assert len(p.frames) == 10 and p.seconds == 1.25  # int(fps x seconds) at i / fps, as nerfstudio's viewer
    back = load_nerfstudio_path(save_nerfstudio_path(p, tmp_path / "k.json"))
    assert [k.time for k in back.keys] == [0.0, 0.5, 1.25]
    for a, b in zip(keys + [Keyframe(c) for c in p.frames], list(back.keys) + [Keyframe(c) for c in back.frames]):
        np.testing.assert_allclose(a.camera.R, b.camera.R, atol=1e-6)
        np.testing.assert_allclose(a.camera.position, b.camera.position, atol=1e-5)
        assert math.isclose(a.camera.fy, b.camera.fy, rel_tol=1e-6) and (b.camera.cx, b.camera.cy) == (W / 2, H / 2)


def test_axes_and_render_of_an_imported_keyframe(bundled_scene, tmp_path):
    """nerfstudio's camera looks down its -z with +y up: the imported keyframe is the camera look_at builds
    looking from the same eye at the same target with the same up (the same float64 operations up to exact sign
    flips, so the same float32 camera), and renders the same image bit for bit."""
    doc = nerfstudio_doc(bundled_scene)
    (tmp_path / "p.json").write_text(json.dumps(doc))
    key = load_nerfstudio_path(tmp_path / "p.json").keys[1].camera
    c, eyes = centre_and_eyes(bundled_scene, 3)
    direct = gb.Camera.look_at(eyes[1], c, UP, W, H, fov_y_deg=55.0)
    assert camera_key(key) == camera_key(direct)
    for s in gb.RenderSettings.parse_list("scalar,gaussian_blending"):
        a = gb.get_renderer(bundled_scene).render(key, s).rgb
        b = gb.get_renderer(bundled_scene).render(direct, s).rgb
        assert np.array_equal(a, b), s.label
    ahead = key.R[2] @ (c - key.position)  # the target is in front (+z of our OpenCV camera) and on the axis
    assert ahead > 0 and np.allclose(key.R[:2] @ (c - key.position), 0, atol=1e-5)
    assert key.R[1] @ UP < 0  # world up is image up: our camera's +y (image down) points against it


def test_cycle_orthographic_and_refusals(bundled_scene, tmp_path):
    doc = nerfstudio_doc(bundled_scene)
    (tmp_path / "c.json").write_text(json.dumps(dict(doc, is_cycle=True)))
    p = load_nerfstudio_path(tmp_path / "c.json")
    assert [k.time for k in p.keys] == pytest.approx([0.0, 0.1, 0.25, 0.35]) and p.keys[-1].camera == p.keys[0].camera
    keys = [{k: v for k, v in e.items() if k != "fov"} | {"view_height": 2.0} for e in doc["keyframes"]]
    path = [{"camera_to_world": e["camera_to_world"], "view_height": 2.0} for e in doc["camera_path"]]
    ortho = dict(doc, camera_type="orthographic", keyframes=keys, camera_path=path)
    (tmp_path / "o.json").write_text(json.dumps(ortho))
    o = load_nerfstudio_path(tmp_path / "o.json")
    assert o.frames[0].orthographic and o.frames[0].fy == H / 2.0
    assert_docs_equal(
        nerfstudio_json(load_nerfstudio_path(save_nerfstudio_path(o, tmp_path / "o2.json"))), nerfstudio_json(o)
    )
    for change, line in [
        (
            {"camera_type": "equirectangular"},
            "camera_type 'equirectangular': gbviewer renders perspective or orthographic cameras only",
        ),
        ({"camera_type": "fisheye"}, "camera_type 'fisheye'"),
        ({"render_width": 0}, "'render_width': expected >= 1"),
        (
            {"camera_path": [{"camera_to_world": [1] * 16, "fov": 50}]},
            "camera_path 0: camera-to-world matrix: expected a last row of 0, 0, 0, 1",
        ),
        ({"camera_path": [{"camera_to_world": gl_look_at([1, 0, 0], [0, 0, 0]), "fov": 190}]}, "camera_path 0: 'fov'"),
        ({"keyframes": "x"}, "'keyframes': expected a list"),
    ]:
        (tmp_path / "bad.json").write_text(json.dumps(dict(doc, **change)))
        with pytest.raises(InvalidValue) as exc:
            load_nerfstudio_path(tmp_path / "bad.json")
        assert line in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_cli_video_along_a_camera_path(bundled_scene, tmp_path, capsys):
    doc = nerfstudio_doc(bundled_scene, frames=5, seconds=0.5)
    src = tmp_path / "camera_path.json"
    src.write_text(json.dumps(doc))
    out = tmp_path / "v.webm"
    assert (
        main(
            [
                "video",
                str(gb.DEFAULT_SCENE),
                "--modes",
                "scalar",
                "--camera-path",
                str(src),
                "--codec",
                "vp9",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    gen = imageio_ffmpeg.read_frames(str(out))
    meta = next(gen)
    assert sum(1 for _ in gen) == 5 and meta["fps"] == 10 and meta["size"][0] == W  # ns-render's 5 / 0.5 s
    frames = nerfstudio_frames(load_nerfstudio_path(src))
    assert [f.camera for f in frames] == list(load_nerfstudio_path(src).frames)
    capsys.readouterr()
    assert (
        main(
            [
                "video",
                str(gb.DEFAULT_SCENE),
                "--camera-path",
                str(src),
                "--frames",
                "3",
                "--out",
                str(tmp_path / "x.mp4"),
            ]
        )
        == 2
    )
    assert capsys.readouterr().err.splitlines() == [
        "gbviewer: error: the camera path file lists its frames; drop --frames and --seconds"
    ]
