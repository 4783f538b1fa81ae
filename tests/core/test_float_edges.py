"""Numbers at the edges of float32 in scenes, cameras and render settings: data loads (non-finite or overflowing
splats dropped with one warning) or fails with one line naming what is wrong; no numpy RuntimeWarning reaches the
user and no render has a non-finite pixel. Header fields of the scene formats under hypothesis."""

from __future__ import annotations

import struct
import subprocess
import sys
import warnings
from pathlib import Path

import fuzz_loaders  # tools/, on sys.path through conftest
import numpy as np
import pytest
from encoders import encode_splat, encode_spz, random_params
from helpers import front_camera, skip_or_fail
from hypothesis import given, settings
from hypothesis import strategies as st

import gbviewer as gb
from gbviewer.core.errors import CameraError, GBViewerError, RenderError
from gbviewer.io import write_inria_ply
from gbviewer.model.scene import MAX_SCALE, MAX_SH
from gbviewer.render import RenderSettings

PACKAGE_ROOT = Path(gb.__file__).resolve().parents[1]  # the gbviewer under test (installed or this tree)
MODES = ["scalar", "mip", "analytic", "gaussian_blending", "wsr", "duplex"]
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def scene_with(n: int = 60, seed: int = 0, means: float = 1.0, **values: float) -> gb.Scene:
    """Splats in front of front_camera() (or spread over +-`means`), with the named arrays set to huge values."""
    rng = np.random.default_rng(seed)
    p = {
        "means": rng.uniform(-1, 1, (n, 3)) * means + (0, 0, 4 if means == 1.0 else 0),
        "scales": np.full((n, 3), 0.05),
        "quats": rng.normal(size=(n, 4)),
        "opacities": np.full(n, 0.5),
        "sh": rng.normal(0, 0.5, (n, 16, 3)),
    }
    for name, value in values.items():
        p[name] = np.where(rng.uniform(size=p[name].shape) < 0.5, value, -value if name != "scales" else value)
    return gb.Scene.from_arrays(**p)


@pytest.mark.parametrize(
    "values",
    [
        dict(means=3e38),
        dict(means=1e20),
        dict(scales=MAX_SCALE),
        dict(sh=MAX_SH),
        dict(quats=3e38),
        dict(opacities=3e38),
        dict(sh=1e29, scales=1e9),
    ],
    ids=lambda v: ",".join(f"{k}={x:g}" for k, x in v.items()),
)
@pytest.mark.parametrize("mode", MODES)
def test_huge_finite_scene_loads_and_renders_finite_pixels(values, mode):
    scene = scene_with(**values)
    frame = gb.render(scene, front_camera(), mode)
    assert np.isfinite(frame.rgb).all() and np.isfinite(frame.alpha).all()


def test_orbit_framing_of_a_huge_scene_is_one_line_or_a_finite_camera():
    with pytest.raises(
        CameraError,
        match=r"^<arrays>: an orbit camera around this scene \(.*\) would sit at .*, "
        "beyond float32; give a camera$",
    ):
        gb.orbit_camera(scene_with(means=3e38))
    cam = gb.orbit_camera(scene_with(means=1e20))
    assert np.isfinite(cam.t).all()
    assert np.isfinite(gb.render(scene_with(means=1e20), cam.with_size(32, 24)).rgb).all()
    lo, hi = scene_with(means=3e38).robust_bounds()
    assert np.isfinite(lo).all() and np.isfinite(hi).all()


def test_overflowing_scales_are_dropped_with_one_warning_or_one_error():
    n = 10
    p = random_params(n)
    p["scales"][0] = 1e20
    p["sh"][1:3, 0] = 1e31
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = gb.Scene.from_arrays(**p)
    assert scene.num_splats == n - 3 and [str(w.message) for w in caught] == [
        f"<arrays>: dropped 3 of {n} splats with non-finite values (or scales over 1e+18, SH over 1e+30)"
    ]
    p["scales"][:] = np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning before the error
        with pytest.raises(GBViewerError, match="^<arrays>: every splat has non-finite values"):
            gb.Scene.from_arrays(**p)


def test_quaternions_near_float32_max_are_normalised():
    p = random_params(4)
    p["quats"] = np.array([[3e38, 0, 0, 0], [0, 3e38, 3e38, 0], [1e-30, 0, 0, 0], [0, 0, 0, 0]])
    q = gb.Scene.from_arrays(**p).quats
    np.testing.assert_allclose(q, [[1, 0, 0, 0], [0, 2**-0.5, 2**-0.5, 0], [1, 0, 0, 0], [1, 0, 0, 0]], atol=1e-6)


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(PACKAGE_ROOT), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-W", "error::RuntimeWarning", "-m", "gbviewer", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=PACKAGE_ROOT,
        timeout=120,
    )  # -m: cwd first


def test_cli_info_and_render_of_huge_scenes(tmp_path):
    for name, spread in (("far", 3e38), ("wide", 1e20)):
        write_inria_ply(scene_with(means=spread, sh=1e29), tmp_path / f"{name}.ply")
    info = run_cli("info", str(tmp_path / "far.ply"))
    assert info.returncode == 0 and info.stderr == ""
    far = run_cli(
        "render", str(tmp_path / "far.ply"), "--out", str(tmp_path / "far.npy"), "--width", "32", "--backend", "cpu"
    )
    assert far.returncode == 2 and not (tmp_path / "far.npy").exists()
    assert len(far.stderr.splitlines()) == 1 and "beyond float32; give a camera" in far.stderr
    wide = run_cli(
        "render", str(tmp_path / "wide.ply"), "--out", str(tmp_path / "wide.npy"), "--width", "32", "--backend", "cpu"
    )  # auto would say its choice on stderr
    assert wide.returncode == 0 and wide.stderr == "", wide.stderr
    assert np.isfinite(np.load(tmp_path / "wide.npy")).all()


@pytest.mark.gl
def test_glsl_renders_huge_scenes_with_finite_pixels():
    from gbviewer.render.glsl import GlslRenderer

    ok, why = GlslRenderer.available()
    if not ok:
        skip_or_fail(why)
    for values in (dict(means=3e38), dict(scales=MAX_SCALE), dict(sh=MAX_SH), dict(sh=1e29, scales=1e9)):
        for mode in MODES:
            frame = gb.render(scene_with(**values), front_camera(), mode, backend="glsl")
            assert np.isfinite(frame.rgb).all() and np.isfinite(frame.alpha).all(), (values, mode)


# ---- render settings and cameras: the Python API validates its numbers ------------------------------------------


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(background=(1e39, 0, 0)), "^background: expected finite float32 numbers, got 1e\\+39$"),
        (dict(background=(0, float("nan"), 0)), "^background: expected finite float32 numbers, got nan$"),
        (dict(background=(0, 0)), "^background: expected 3 numbers"),
        (dict(background="red"), "^background: expected 3 numbers"),
        (dict(supersample=0), "^supersample: expected >= 1, got 0$"),
        (dict(supersample=9), "^supersample: expected <= 8"),
        (dict(supersample=2.5), "^supersample: expected an integer, got 2.5$"),
        (dict(sh_degree=4), "^sh_degree: expected <= 3, got 4$"),
        (dict(sh_degree=-1), "^sh_degree: expected >= 0"),
        (dict(threads=-1), "^threads: expected >= 0"),
        (dict(threads=2**40), "^threads: expected <= 1024"),
        (dict(et_grade=0.0), "^et_grade: expected > 0"),
        (dict(et_grade=float("inf")), "^et_grade: expected a finite"),
        (dict(et_grade=1e39), "^et_grade: expected a finite float32"),
        (dict(cell_size=0), "^cell_size: expected >= 1"),
        (dict(cell_size=10**30), "^cell_size: expected <= "),
    ],
)
def test_render_settings_refuse_bad_numbers_with_one_line(options, message):
    with pytest.raises(RenderError, match=message):
        RenderSettings(**options)


def test_render_settings_keep_good_numbers():
    s = RenderSettings("duplex", 2.0, [0.25, 0.5, 1], np.int64(2), threads=4, et_grade=3, cell_size=np.int32(7))
    assert (s.supersample, s.background, s.sh_degree, s.et_grade, s.cell_size) == (2, (0.25, 0.5, 1.0), 2, 3.0, 7)
    assert type(s.supersample) is int and type(s.et_grade) is float


@pytest.mark.parametrize(
    "changes, message",
    [
        (dict(width=0), "width: expected >= 1"),
        (dict(height=16385), "height: expected <= 16384"),
        (dict(width="wide"), "width: expected an integer"),
        (dict(fx=0.0), "fx: expected > 0"),
        (dict(fy=1e39), "fy: expected a finite float32"),
        (dict(cx=float("nan")), "cx: expected a finite"),
        (dict(near=-1.0), "near: expected > 0"),
        (dict(t=[0, 0, 1e39]), "t: expected finite float32 numbers"),
        (dict(t=[0, 0]), "t: expected 3 numbers"),
        (dict(R=np.full((3, 3), np.nan)), "R: expected finite"),
        (dict(R=np.diag([1.0, 1, -1])), "R is not a rotation matrix"),
    ],
)
def test_camera_refuses_bad_numbers_with_one_line(changes, message):
    args = dict(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0, R=np.eye(3), t=np.zeros(3), name="c")
    with pytest.raises(CameraError, match=f"^camera 'c': {message}"):
        gb.Camera(**{**args, **changes})


def test_sampling_rates_at_the_edges():
    from gbviewer.model.camera import parse_rate

    cam = front_camera()
    for bad in (0, -1, float("inf"), float("nan"), 1e300):
        with pytest.raises(CameraError, match="^sampling rate: expected"):
            cam.at_sampling_rate(bad)
    for text in ("1e400", "1/0", "x", "nan"):
        with pytest.raises(GBViewerError, match=f"^sampling rate '{text}': expected"):
            parse_rate(text)
    assert cam.at_sampling_rate(1e-300).width == 1


# ---- header fields of the scene formats -------------------------------------------------------------------------


def check(tmp: Path, data: bytes) -> None:
    path = tmp / "scene"
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the one "dropped N splats" warning is the intended outcome
        assert fuzz_loaders.check_load(path) in ("ok", "error")


F32 = st.floats(width=32, allow_nan=True, allow_infinity=True)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(F32, F32), min_size=1, max_size=8))
def test_splat_records_with_any_float32_position_and_scale(tmp_path_factory, values):
    p = random_params(len(values))
    p["means"][:, 0] = [v[0] for v in values]
    p["scales"][:, 1] = [v[1] for v in values]
    with np.errstate(invalid="ignore"):
        check(tmp_path_factory.mktemp("splat"), encode_splat(p))


@settings(max_examples=100, deadline=None)
@given(
    version=st.integers(0, 6),
    count=st.integers(0, 2**32 - 1),
    degree=st.integers(0, 255),
    frac=st.integers(0, 255),
    flags=st.integers(0, 255),
    gzipped=st.booleans(),
)
def test_spz_header_fields(tmp_path_factory, version, count, degree, frac, flags, gzipped):
    import gzip

    raw = gzip.decompress(encode_spz(random_params(20, 1), 3))
    head = struct.pack("<4sIIBBBB", b"NGSP", version, count, degree, frac, flags, 0)
    body = head + raw[16:]
    check(tmp_path_factory.mktemp("spz"), gzip.compress(body) if gzipped else body)


@settings(max_examples=100, deadline=None)
@given(
    count=st.one_of(st.integers(-5, 10**30).map(str), st.sampled_from(["1e3", "nan", "9" * 5000, "0x10", ""])),
    value=st.floats(width=32, allow_nan=True, allow_infinity=True),
)
def test_ply_vertex_count_and_values(tmp_path_factory, count, value):
    tmp = tmp_path_factory.mktemp("ply")
    scene = gb.Scene.from_arrays(**random_params(3))
    write_inria_ply(scene, tmp / "a.ply")
    data = (tmp / "a.ply").read_bytes()
    data = data.replace(b"element vertex 3", f"element vertex {count}".encode(), 1)
    end = data.index(b"end_header\n") + len(b"end_header\n")
    check(tmp, data[:end] + np.float32(value).tobytes() + data[end + 4 :])
