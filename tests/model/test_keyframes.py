"""Keyframed camera paths (gbviewer.model.keyframes): exact at the keys, smooth between them, JSON forms and round
trip."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import OUTPUT_H as H
from helpers import OUTPUT_W as W

import gbviewer as gb
from gbviewer.core.errors import InvalidValue
from gbviewer.model import keyframes
from gbviewer.model.camera_paths import keyframe_path


def keys_for(bundled_scene) -> list[keyframes.Keyframe]:
    cams = [
        gb.orbit_camera(bundled_scene, az, el, width=W, height=H)
        for az, el in ((0, 10), (70, 30), (150, -20), (200, 40))
    ]
    cams[2] = cams[2].with_size(W, H)
    cams[1] = replace(cams[1], fx=cams[1].fx * 1.7, fy=cams[1].fy * 1.7, cx=50.0)
    return [keyframes.Keyframe(c, r, t) for c, r, t in zip(cams, (1.0, 0.5, 0.125, 2.0), (0.0, 0.5, 2.0, 3.0))]


def test_keyframes_pass_exactly_through_their_keys(bundled_scene):
    keys = keys_for(bundled_scene)
    at = keyframes.interpolate_keyframes(keys, [k.time for k in keys])
    for k, g in zip(keys, at):
        for field in ("fx", "fy", "cx", "cy"):
            assert math.isclose(getattr(g.camera, field), getattr(k.camera, field), rel_tol=1e-12)
        np.testing.assert_allclose(g.camera.R, k.camera.R, atol=1e-12)
        np.testing.assert_allclose(g.camera.t, k.camera.t, atol=1e-12)
        assert math.isclose(g.rate, k.rate, rel_tol=1e-12) and g.time == k.time
    # between keys: a proper rotation, continuous, rates inside the keys' range (monotone, no overshoot)
    ts = np.linspace(0, 3, 301)
    path = keyframes.interpolate_keyframes(keys, ts)
    for a, b in zip(path, path[1:]):
        assert np.abs(a.camera.R @ a.camera.R.T - np.eye(3)).max() < 1e-9
        assert (
            np.abs(a.camera.R - b.camera.R).max() < 0.05 and np.linalg.norm(a.camera.position - b.camera.position) < 0.1
        )
    rates = np.array([p.rate for p in path])
    assert rates.min() >= 0.125 - 1e-12 and rates.max() <= 2.0 + 1e-12
    # a keyframe path whose frames fall on the key times renders the keys' cameras
    frames = keyframe_path(keys, 7)  # frames every 0.5 s: keys at frames 0, 1, 4, 6
    for i, k in zip((0, 1, 4, 6), keys):
        want = k.camera.at_sampling_rate(k.rate)
        assert (frames[i].camera.width, frames[i].camera.height) == (want.width, want.height)
        np.testing.assert_allclose(frames[i].camera.R, want.R, atol=1e-12)
        assert frames[i].rate == pytest.approx(k.rate, rel=1e-12) and (frames[i].width, frames[i].height) == (W, H)


def test_two_keys_slerp_the_rotation(output_view):

    def rot_y(deg):
        a = math.radians(deg)
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    k0 = keyframes.Keyframe(replace(output_view, R=np.eye(3), t=np.zeros(3)))
    k1 = keyframes.Keyframe(replace(output_view, R=rot_y(90), t=np.zeros(3)))
    mid = keyframes.interpolate_keyframes([k0, k1], [0.25, 0.5])
    np.testing.assert_allclose(mid[0].camera.R, rot_y(22.5), atol=1e-12)
    np.testing.assert_allclose(mid[1].camera.R, rot_y(45), atol=1e-12)


def test_keyframes_json_forms_and_round_trip(bundled_scene, output_view, tmp_path):
    doc = {
        "keyframes": [
            {"time": 0, "orbit": [30, 20, 0]},
            {"time": 1, "position": [0.5, -0.5, 2.0], "look_at": [0, 0, 0], "rate": "1/4", "fov_y_deg": 40},
            {"time": 2, "R": np.eye(3).tolist(), "t": [0, 0, 3], "rate": 0.5},
            {"time": 3, "rotation": np.eye(3).tolist(), "position": [0, 0, -4]},
        ]
    }
    f = tmp_path / "keys.json"
    f.write_text(json.dumps(doc))
    keys = keyframes.load_keyframes(f, output_view, bundled_scene)
    assert [k.rate for k in keys] == [1.0, 0.25, 0.5, 1.0]
    np.testing.assert_allclose(keys[0].camera.R, output_view.R, atol=1e-12)  # output_view is the same orbit
    np.testing.assert_allclose(keys[3].camera.t, [0, 0, 4])
    assert math.isclose(keys[1].camera.fy, 0.5 * H / math.tan(math.radians(20)))
    g = tmp_path / "again.json"
    g.write_text(json.dumps(keyframes.keyframes_to_json(keys)))
    again = keyframes.load_keyframes(g, output_view, bundled_scene)
    for a, b in zip(keys, again):
        np.testing.assert_array_equal(a.camera.R, b.camera.R)
        assert (a.camera.fx, a.rate, a.time) == (b.camera.fx, b.rate, b.time)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"time": 1, "orbit": [0, 0, 0]}, {"time": 0, "orbit": [9, 0, 0]}]))
    with pytest.raises(gb.GBViewerError, match="increasing"):
        keyframes.load_keyframes(bad, output_view, bundled_scene)


def test_orthographic_keys_round_trip(bundled_scene, output_view, tmp_path):
    """A key's projection is read (default: the base camera's), written and read back; a key that switches the
    projection gives its scale; keys of both projections are not interpolated into one path."""
    ortho = output_view.with_projection("orthographic", 3.0)
    f = tmp_path / "keys.json"
    f.write_text(json.dumps([{"orbit": [30, 20, 0]}, {"orbit": [60, 20, 0], "fx": 9.0, "fy": 9.0}]))
    keys = keyframes.load_keyframes(f, ortho, bundled_scene)
    assert [k.camera.projection for k in keys] == ["orthographic"] * 2 and keys[1].camera.fx == 9.0
    g = tmp_path / "again.json"
    g.write_text(json.dumps(keyframes.keyframes_to_json(keys)))
    again = keyframes.load_keyframes(g, output_view, bundled_scene)  # a perspective base: the file says otherwise
    assert [k.camera.projection for k in again] == ["orthographic"] * 2
    assert [(k.camera.fx, k.camera.fy) for k in again] == [(k.camera.fx, k.camera.fy) for k in keys]
    mid = keyframes.interpolate_keyframes(again, [0.5])[0].camera
    assert mid.orthographic and keys[1].camera.fx < mid.fx < keys[0].camera.fx
    mixed = [again[0], keyframes.Keyframe(output_view)]
    with pytest.raises(gb.GBViewerError, match="same projection"):
        keyframes.interpolate_keyframes(mixed, [0.5])


@pytest.mark.parametrize(
    "key, message",
    [
        ({"orbit": [0, 0], "projection": "fisheye"}, "keyframe 0: 'projection': expected perspective or orthographic"),
        ({"orbit": [0, 0], "projection": "orthographic"}, "give 'fx' and 'fy' too"),
        ({"orbit": [0, 0], "projection": "orthographic", "fx": 5, "fy": 5, "fov_y_deg": 40}, "'fov_y_deg' has no"),
    ],
)
def test_bad_projection_keys(bundled_scene, output_view, tmp_path, key, message):
    f = tmp_path / "keys.json"
    f.write_text(json.dumps([key]))
    with pytest.raises(gb.GBViewerError, match=message):
        keyframes.load_keyframes(f, output_view, bundled_scene)


@pytest.mark.parametrize(
    "keys, message",
    [
        ([{"orbit": [0, 0], "rat": 2}], "keyframe 0: unknown field 'rat'"),
        (
            [{"orbit": [0, 0]}, {"orbit": [0, 0], "position": [0, 0, 1], "look_at": [0, 0, 0]}],
            "keyframe 1: 'look_at' and 'orbit' are two poses",
        ),
        ([{"orbit": [0, 0], "position": [0, 0, 1]}], "keyframe 0: 'position' does not belong to a 'orbit' pose"),
        ([{"R": np.eye(3).tolist(), "t": [0, 0, 3], "up": [0, 1, 0]}], "keyframe 0: 'up' does not belong"),
        ([{"orbit": [0, 0], "fov_y_deg": 40, "fx": 50}], "keyframe 0: 'fov_y_deg' and 'fx' both set"),
        ([{"orbit": [0, 0], "time": "0"}], "keyframe 0: 'time': expected a JSON number, got the string '0'"),
        ([{"orbit": ["30", 0]}], "keyframe 0: 'orbit' azimuth: expected a JSON number"),
        (
            [{"orbit": [0, 0]}, {"orbit": [9, 0], "projection": "orthographic", "fx": 5, "fy": 5}],
            "keyframe 1: 'projection' orthographic differs from keyframe 0's",
        ),
    ],
)
def test_keyframe_mistakes_are_refused(bundled_scene, output_view, tmp_path, keys, message):
    """A typo, a second pose, two ways of giving the intrinsics, a number as text or mixed projections: one line
    naming the file, the key and the field (not a silently ignored field)."""
    f = tmp_path / "keys.json"
    f.write_text(json.dumps(keys))
    with pytest.raises(InvalidValue, match=message) as info:
        keyframes.load_keyframes(f, output_view, bundled_scene)
    assert str(info.value).startswith(f"{f}: ") and "\n" not in str(info.value)
