"""The JSON readers (cameras.json, keyframe files): hostile documents give one line naming the file, the entry and
the key, never a traceback; whatever they accept is a list of finite, valid cameras. Hypothesis mutates valid
documents with odd values, odd types and missing keys."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import front_camera, random_scene
from hypothesis import given, settings
from hypothesis import strategies as st

import gbviewer as gb
from gbviewer.core.errors import CameraError, InvalidValue
from gbviewer.core.validate import F32_MAX
from gbviewer.model import keyframes
from gbviewer.model.camera import MAX_IMAGE_SIZE

HUGE = "HUGE_INT"  # replaced by a 5000-digit integer literal in the JSON text (json.dumps refuses to write one)
PACKAGE_ROOT = Path(gb.__file__).resolve().parents[1]  # the gbviewer under test (installed or this tree)


def entry(k: int = 0) -> dict:
    return {
        "id": k,
        "img_name": f"{k:05d}",
        "width": 800,
        "height": 600,
        "fx": 700.0,
        "fy": 710.0,
        "position": [1.0, -2.0, 0.5],
        "rotation": np.eye(3).tolist(),
    }


def write(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc).replace(f'"{HUGE}"', "9" * 5000))
    return path


def assert_one_line(exc: Exception, path: Path) -> None:
    text = str(exc)
    assert "\n" not in text and text.startswith(str(path)), text


@pytest.mark.parametrize(
    "change, message",
    [
        ({"width": "abc"}, "entry 1: 'width': expected an integer, got 'abc'"),
        ({"width": HUGE}, "not valid JSON \\(Exceeds the limit \\(4300 digits\\)"),
        ({"height": 0}, "entry 1: 'height': expected >= 1, got 0"),
        ({"width": MAX_IMAGE_SIZE + 1}, f"entry 1: 'width': expected <= {MAX_IMAGE_SIZE}"),
        ({"fx": -1}, "entry 1: 'fx': expected > 0, got -1"),
        ({"fy": 1e39}, "entry 1: 'fy': expected a finite float32 number"),
        ({"fx": {"a": 1}}, "entry 1: 'fx': expected a number"),
        ({"position": [0, 0]}, "entry 1: 'position': expected 3 numbers"),
        ({"position": {"x": 0}}, "entry 1: 'position': expected 3 numbers"),
        ({"position": [0, 0, 1e39]}, "entry 1: 'position': expected finite float32 numbers, got 1e\\+39"),
        ({"rotation": [[1, 0, 0], [0, 1, 0]]}, "entry 1: 'rotation': expected a 3x3 matrix"),
        ({"rotation": np.diag([1.0, 1.0, -1.0]).tolist()}, "entry 1: camera '00001': R is not a rotation matrix"),
        ({"rotation": (np.eye(3) * 1.01).tolist()}, "entry 1: camera '00001': R is not a rotation matrix"),
        ({"fx": None}, "entry 1: 'fx': expected a number, got None"),
    ],
)
def test_cameras_json_bad_field_is_one_line_naming_entry_and_key(tmp_path, change, message):
    path = write(tmp_path / "cams.json", [entry(0), {**entry(1), **change}])
    with pytest.raises(CameraError, match=f"^{tmp_path / 'cams.json'}: {message}") as info:
        gb.load_cameras_json(path)
    assert_one_line(info.value, path)


@pytest.mark.parametrize(
    "text, message",
    [
        ('[{"width": Infinity}]', "not a finite number"),
        ("[" * 100 + "]" * 100, "nested deeper"),
        ("{}", "non-empty"),
        ("[]", "non-empty"),
        ("[1]", "entry 0: expected a JSON object, got int"),
        ("[{}]", "entry 0: missing 'width'"),
        ('{"width": 1}', "non-empty JSON list"),
        ("\xff\xfe", "not valid JSON"),
        ("", "not valid JSON"),
        ('[{"width": 64, "width": 32}]', "key 'width' given twice with different values"),
    ],
)
def test_cameras_json_bad_document_is_one_line(tmp_path, text, message):
    path = tmp_path / "cameras.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(CameraError, match=message) as info:
        gb.load_cameras_json(path)
    assert_one_line(info.value, path)


@pytest.mark.parametrize(
    "reader",
    [
        "gb.load_cameras_json(path)",
        "from gbviewer.app.settings import load_settings; print(load_settings(path)[1])",
    ],
)
def test_a_json_input_that_is_a_fifo_is_one_line_without_blocking(tmp_path, reader):
    """--cameras (or the viewer's settings.json) naming a FIFO blocked in open() until a writer came: forever."""
    path = tmp_path / "cameras.json"
    os.mkfifo(path)
    code = (
        "import sys, gbviewer as gb; from pathlib import Path\npath = Path(sys.argv[1])\ntry:\n"
        f"    {reader}\nexcept gb.GBViewerError as e:\n    print(e)"
    )
    run = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert f"{path}: cannot read (not a regular file)" in run.stdout


def test_cameras_json_missing_file_and_folder(tmp_path):
    for path in (tmp_path / "none.json", tmp_path):
        with pytest.raises(CameraError, match="cannot read") as info:
            gb.load_cameras_json(path)
        assert_one_line(info.value, path)


def test_cli_bad_cameras_json_exits_2_with_one_line(tmp_path):
    cams = write(tmp_path / "cams.json", [{**entry(0), "width": "abc"}])
    out = tmp_path / "out.npy"
    proc = subprocess.run(
        [
            sys.executable,
            "-W",
            "error::RuntimeWarning",
            "-m",
            "gbviewer",
            "render",
            str(gb.DEFAULT_SCENE),
            "--cameras",
            str(cams),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(PACKAGE_ROOT), "PATH": "/usr/bin:/bin"},
        cwd=PACKAGE_ROOT,
        timeout=120,
    )  # -m puts the working folder first on sys.path
    assert proc.returncode == 2 and not out.exists()
    assert proc.stderr.strip().splitlines() == [
        f"gbviewer: error: {cams}: entry 0: 'width': expected an integer, got 'abc'"
    ]


ODD = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.just(HUGE),
    st.floats(allow_nan=False),
    st.integers(-(10**20), 10**20),
    st.lists(st.floats(-1e40, 1e40), max_size=4),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
    st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), min_size=3, max_size=3),
)


@st.composite
def mutated(draw, valid: list[dict]) -> list:
    """Valid entries with some keys replaced by odd values or deleted, or whole entries replaced."""
    doc = []
    for e in valid:
        e = dict(e)
        for key in draw(st.lists(st.sampled_from(sorted(e)), max_size=3, unique=True)):
            if draw(st.booleans()):
                del e[key]
            else:
                e[key] = draw(ODD)
        doc.append(draw(ODD) if draw(st.integers(0, 9)) == 0 else e)
    return doc


def assert_valid_camera(c: gb.Camera) -> None:
    assert 1 <= c.width <= MAX_IMAGE_SIZE and 1 <= c.height <= MAX_IMAGE_SIZE and c.fx > 0 and c.fy > 0
    assert np.isfinite(c.R).all() and np.isfinite(c.t).all() and np.abs(c.t).max() <= F32_MAX
    assert all(math.isfinite(v) and abs(v) <= F32_MAX for v in (c.fx, c.fy, c.cx, c.cy))
    np.testing.assert_allclose(c.R @ c.R.T, np.eye(3), atol=2e-3)


@settings(max_examples=200, deadline=None)
@given(mutated([entry(0), entry(1)]))
def test_cameras_json_property(tmp_path_factory, doc):
    path = write(tmp_path_factory.mktemp("cams") / "cameras.json", doc)
    try:
        cams = gb.load_cameras_json(path)
    except CameraError as exc:
        assert_one_line(exc, path)
    else:
        assert len(cams) == len(doc)
        for c in cams:
            assert_valid_camera(c)


# ---- keyframes -------------------------------------------------------------------------------------------------

SCENE = random_scene(50)
BASE = front_camera()
KEYS = [
    {"time": 0, "orbit": [30, 20, 0]},
    {"time": 1, "position": [0.5, -0.5, 2.0], "look_at": [0, 0, 0], "rate": "1/4", "fov_y_deg": 40},
    {"time": 2, "R": np.eye(3).tolist(), "t": [0, 0, 3], "rate": 0.5, "fx": 50, "cx": 10},
    {"time": 3, "rotation": np.eye(3).tolist(), "position": [0, 0, -4]},
]


@pytest.mark.parametrize(
    "index, change, message",
    [
        (1, {"position": [0, 0]}, "keyframe 1: 'position': expected 3 numbers"),
        (1, {"look_at": [0, 0, "x"]}, "keyframe 1: 'look_at': expected 3 numbers"),
        (1, {"fov_y_deg": 180}, "keyframe 1: 'fov_y_deg': expected <= 179"),
        (1, {"rate": "1/0"}, "keyframe 1: 'rate': expected > 0, got 0"),
        (1, {"rate": "1e400"}, "keyframe 1: 'rate': expected a finite number"),
        (1, {"rate": 0}, "keyframe 1: 'rate': expected >= 0.001, got 0"),
        (2, {"t": [0, 0, 1e39]}, "keyframe 2: 't': expected finite float32 numbers"),
        (2, {"fx": -3}, "keyframe 2: 'fx': expected > 0"),
        (2, {"cx": HUGE}, "not valid JSON"),
        (2, {"cx": [1]}, "keyframe 2: 'cx': expected a number"),
        (2, {"R": (2 * np.eye(3)).tolist()}, "keyframe 2: camera 'key2': R is not a rotation matrix"),
        (0, {"orbit": [30]}, "keyframe 0: 'orbit': expected \\[azimuth, elevation\\]"),
        (0, {"orbit": [30, "up", 1]}, "keyframe 0: 'orbit' elevation: expected a JSON number"),
        (0, {"orbit": [30, 20, 1e39]}, "keyframe 0: 'orbit' distance: expected a finite float32"),
        (3, {"time": "soon"}, "keyframe 3: 'time': expected a JSON number"),
        (3, {"time": 0.5}, "times must be finite and strictly increasing"),
        (3, {"rotation": None}, "keyframe 3: 'rotation': expected a 3x3 matrix"),
    ],
)
def test_keyframes_bad_field_is_one_line(tmp_path, index, change, message):
    doc = [dict(k) for k in KEYS]
    doc[index].update(change)
    path = write(tmp_path / "keys.json", {"keyframes": doc})
    with pytest.raises(InvalidValue, match=message) as info:
        keyframes.load_keyframes(path, BASE, SCENE)
    assert_one_line(info.value, path)


@pytest.mark.parametrize(
    "doc, message",
    [
        ({"keyframes": {}}, "non-empty list"),
        ([5], "keyframe 0: expected a JSON object, got int"),
        ([{"time": 0}], "keyframe 0: no pose"),
        ([{"R": np.eye(3).tolist()}], "keyframe 0: missing 't'"),
    ],
)
def test_keyframes_bad_document_is_one_line(tmp_path, doc, message):
    path = write(tmp_path / "keys.json", doc)
    with pytest.raises(InvalidValue, match=message) as info:
        keyframes.load_keyframes(path, BASE, SCENE)
    assert_one_line(info.value, path)


def test_keyframes_orbit_needs_the_scene(tmp_path):
    path = write(tmp_path / "keys.json", [{"orbit": [0, 0]}])
    with pytest.raises(InvalidValue, match="'orbit' keys need the scene"):
        keyframes.load_keyframes(path, BASE)
    assert len(keyframes.load_keyframes(path, BASE, SCENE)) == 1


@settings(max_examples=150, deadline=None)
@given(mutated(KEYS))
def test_keyframes_property(tmp_path_factory, doc):
    path = write(tmp_path_factory.mktemp("keys") / "keys.json", {"keyframes": doc})
    try:
        keys = keyframes.load_keyframes(path, BASE, SCENE)
    except InvalidValue as exc:
        assert_one_line(exc, path)
    else:
        for k in keys:
            assert_valid_camera(k.camera)
            assert math.isfinite(k.rate) and k.rate > 0 and (k.time is None or math.isfinite(k.time))
