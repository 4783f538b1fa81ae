"""The CPU blend's SIMD paths (scalar, avx2, avx512; aarch64: neon) against each other and against the float64
reference.

The preprocess (gbv/preprocess.h) runs on the same SIMD path as the blend (8 or 16 splats per call) and is bit-identical
to the scalar path's: every Splat2D field, tile rectangle and culling decision (test_preprocess_bitwise).

Tolerance between a vector path and the scalar path: the vector exp (Highway, 1 ulp) and libm's expf differ by up to
1 ulp, and FMA contraction differs, so colours and alphas agree to ~1e-6 (asserted: 1e-5) except where an alpha within
~1e-6 of the 1/255 (1/256) cut, or a transmittance that close to the 1e-4 stop, is decided the other way. One flipped
decision costs up to ~alpha x colour (< 2e-2, as in test_render_reference's ties) in that pixel (and, in Gaussian
Blending, a slightly different window for later splats there). Such pixels are counted: at most FLIP_FRACTION of an
image's pixels plus 2. Visible splats, sort lengths and tile-list entries are identical (preprocess is shared).

Every path the CPU has runs; a path the CPU lacks (AVX-512 on an AVX2 machine) is skipped with that reason.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from contextlib import contextmanager

import numpy as np
import pytest
from helpers import random_view, skip_or_fail
from test_render_reference import BACKGROUND, SCENES, _check_strict

import gbviewer as gb
from gbviewer import _native, lod
from gbviewer.model.cells import build_cells
from gbviewer.render import create_renderer

ALL_PATHS = ("scalar", "avx2", "avx512", "neon")
VECTOR_PATHS = ("avx2", "avx512", "neon")
MODES = ("scalar", "mip", "analytic", "gaussian_blending", "wsr", "duplex")
TOL = 1e-5
FLIP_FRACTION = 2e-3
FLIP_MAX_ERR = 2e-2


@contextmanager
def simd(path: str):
    """Renders inside use `path`; skips when this CPU or build has no such path."""
    if path not in _native.simd_paths():
        pytest.skip(f"this CPU/build has no {path} path (it has {', '.join(_native.simd_paths())})")
    before = _native.simd()
    _native.testing.set_simd(path)
    try:
        yield
    finally:
        _native.testing.set_simd(before)


def render(path, scene, cam, mode, supersample=1, **kw):
    """A frame on `path` from a renderer of its own: a renderer keeps its per-camera stage, and one that another
    path built would be reused (the paths' stages would then never be compared)."""
    with simd(path):
        renderer = create_renderer("cpu")
        renderer.upload(scene)
        return renderer.render(cam, gb.RenderSettings.parse(mode, supersample=supersample, **kw))


def assert_close_to_scalar(vec, ref, what):
    tol, fraction, max_err = TOL, FLIP_FRACTION, FLIP_MAX_ERR
    for name in ("visible", "sort_length", "pairs"):
        assert getattr(vec.stats, name) == getattr(ref.stats, name), f"{what}: {name} differs"
    diff = np.maximum(np.abs(vec.rgb - ref.rgb).max(axis=2), np.abs(vec.alpha - ref.alpha))
    flips = diff > tol
    allowed = 2 + fraction * diff.size
    assert flips.sum() <= allowed, f"{what}: {flips.sum()} pixels beyond {tol} (allowed {allowed:.0f})"
    assert diff.max() <= max_err, f"{what}: max difference {diff.max():.2e}"
    evals_differ = (vec.debug["evals"] != ref.debug["evals"]).sum()
    assert evals_differ <= allowed, f"{what}: {evals_differ} pixels stop at another list entry"
    assert np.isfinite(vec.rgb).all() and np.isfinite(vec.alpha).all()


def test_paths_and_stats():
    paths = _native.simd_paths()
    assert paths[0] == "scalar" and set(paths) <= set(ALL_PATHS) and _native.simd() in paths
    if sys.platform.startswith("linux") and os.uname().machine == "x86_64" and "avx2" in _cpu_flags():
        assert "avx2" in paths, "an AVX2 CPU should get the avx2 path"
    scene, cam = random_view(1, n=40)
    for path in paths:
        assert render(path, scene, cam, "scalar").stats.simd == path
    assert gb.render(scene, cam).stats.simd == _native.simd()


@pytest.mark.parametrize(
    "mode, ran",
    [
        ("stopthepop", "scalar"),
        ("stopthepop:0", "scalar"),
        ("eval3d", "scalar"),
        ("stochastic_popfree", None),
        ("stochastic", None),
        ("gaussian_blending", None),
    ],
)
def test_stats_name_the_path_the_blend_ran(mode, ran):
    """FrameStats.simd is the path the blend ran: the per-pixel sorted modes walk one pixel at a time (no vector
    lanes) whichever path is selected; the others run the selected one."""
    scene, cam = random_view(1, n=40)
    for path in _native.simd_paths():
        assert render(path, scene, cam, mode).stats.simd == (ran or path), (mode, path)


def _cpu_flags() -> set[str]:
    try:
        text = open("/proc/cpuinfo").read()
    except OSError:
        return set()
    return set(next((ln.split(":")[1].split() for ln in text.splitlines() if ln.startswith("flags")), []))


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("supersample", [1, 2, 3])
def test_vector_matches_scalar_random(path, mode, supersample):
    for seed, sh_degree, filter3d in SCENES[:2]:
        scene, cam = random_view(seed, n=300, sh_degree=sh_degree, filter3d=filter3d, W=61, H=37)
        ref = render("scalar", scene, cam, mode, supersample, debug="window" if mode == "gaussian_blending" else "none")
        vec = render(path, scene, cam, mode, supersample, debug="window" if mode == "gaussian_blending" else "none")
        assert_close_to_scalar(vec, ref, f"{path} {mode} x{supersample} seed {seed}")
        if mode == "gaussian_blending":
            assert np.abs(vec.debug["window"] - ref.debug["window"]).mean() < 1e-4


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
def test_vector_matches_scalar_bundled(path, mode, bundled_scene):
    scene = bundled_scene
    cam = gb.orbit_camera(scene, 40, 25, width=160, height=120)
    for c in (cam, cam.at_sampling_rate(1 / 4)):
        assert_close_to_scalar(render(path, scene, c, mode), render("scalar", scene, c, mode), f"{path} {mode}")


@pytest.mark.parametrize("path", ALL_PATHS)
@pytest.mark.parametrize("mode", ["scalar", "mip", "analytic"])
def test_reference_through_each_path(path, mode):
    """The float64 reference test (strict 1e-4, ties excepted) holds on every path, not only the default one."""
    seed, sh_degree, filter3d = SCENES[1]
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d)
    with simd(path):
        for supersample in (1, 2):
            frame = gb.render(scene, cam, mode=mode, supersample=supersample, background=BACKGROUND)
            _check_strict(frame, scene, cam, mode, supersample)


@pytest.mark.parametrize("path", ALL_PATHS)
def test_reference_gaussian_blending_each_path(path):
    seed, sh_degree, filter3d = SCENES[0]
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d, max_px_sigma=1.5)
    with simd(path):
        frame = gb.render(scene, cam, mode="gaussian_blending", background=BACKGROUND)
        _check_strict(frame, scene, cam, "gaussian_blending", 1)


# captured_preprocess(): per splat its valid byte, then (when valid) Splat2D and TileRect, zeros when culled
SPLAT2D = np.dtype(
    [
        ("xy", "<u4", 2),
        ("depth", "<u4"),
        ("opacity", "<u4"),
        ("conic", "<u4", 3),
        ("color", "<u4", 3),
        ("v1", "<u4", 2),
        ("sigma", "<u4", 2),
        ("inv_sigma", "<u4", 2),
        ("log_min_alpha", "<u4"),
        ("radius", "<u4"),
        ("cell", "<i4"),
        ("id", "<i4"),
    ]
)
PREPROCESS_RECORD = np.dtype([("valid", "u1"), ("splat", SPLAT2D), ("rect", "<i4", 4)])


def preprocessed(path, scene, cam, mode, **kw):
    """The preprocess output of a render on `path`, as PREPROCESS_RECORD per splat, and the frame."""
    _native.testing.set_capture_preprocess(True)
    try:
        frame = render(path, scene, cam, mode, **kw)
        rec = np.frombuffer(_native.testing.captured_preprocess(), PREPROCESS_RECORD)
    finally:
        _native.testing.set_capture_preprocess(False)
    assert len(rec) == scene.num_splats
    return rec, frame


def _cut_scene(seed):
    """Splats at the preprocess's cuts: opacities at and next to 1/255 and 1/256 (after the mip compensation too),
    depths at and next to the near plane, view weights near 0 (a sum of terms), 3D filters, subnormal and zero
    scales; n = 1003 leaves a partial vector at the end."""
    rng = np.random.default_rng(seed)
    n = 1003
    z = rng.uniform(0.15, 8.0, n)
    z[:40] = np.nextafter(np.float32(0.2), np.float32([0.0, 1.0] * 20))
    means = np.c_[rng.uniform(-1.3, 1.3, n) * z, rng.uniform(-1.3, 1.3, n) * z, z]
    scales = np.exp(rng.uniform(np.log(1e-4), np.log(0.5), (n, 3)))
    scales[40:60] = 0.0
    scales[60:80, :2] = 1e-38
    op = rng.uniform(0.003, 1.0, n).astype(np.float32)
    for i, o in enumerate((1 / 255, 1 / 256)):
        base = np.float32(o)
        op[100 + 30 * i : 130 + 30 * i] = np.nextafter(base, np.float32([0.0, 1.0, 1.0] * 10))
        op[160 + 10 * i : 170 + 10 * i] = base
    quats = rng.normal(size=(n, 4))
    quats[80:90] = 0.0
    sh = rng.uniform(-1, 1, (n, 16, 3))
    vw = rng.normal(0.0, 0.4, (n, 16))
    vw[:, 0] = rng.uniform(-0.5, 4.0, n)
    vw[200:300, 1:] = 0.0
    vw[200:300, 0] = np.float32(rng.choice([0.0, 1e-30, -1e-30, 1e-3], 100))
    f3d = np.where(rng.random(n) < 0.5, rng.uniform(0.0, 0.05, n), 0.0)
    scene = gb.Scene.from_arrays(
        means, scales, quats, op, sh, f3d, view_weight_sh=vw, wsr_sigma=5.0, weight_background=0.3
    )
    R = np.array([[0.98, -0.17, 0.1], [0.17, 0.985, 0.0], [-0.1, 0.02, 0.995]])
    R = np.linalg.qr(R)[0] * np.sign(np.diag(np.linalg.qr(R)[1]))
    return scene, gb.Camera(97, 61, 52.3, 47.9, 50.1, 29.7, R, np.array([0.03, -0.02, 0.1]))


def _gapped_scene():
    """16 splats, all on screen but splat 14 (behind the camera), SH degree 3: the stage's second colour group holds
    splats 8-13 and 15 with a spare lane, whose first and last rows are 7 apart though they are not 8 consecutive rows
    (a vector path that took them for a run would read splat 14's mean for splat 15's view direction)."""
    rng = np.random.default_rng(3)
    n = 16
    means = np.c_[rng.uniform(-1, 1, n), rng.uniform(-0.6, 0.6, n), rng.uniform(2.5, 4, n)]
    means[14, 2] = -1.0
    quats = rng.normal(size=(n, 4))
    scene = gb.Scene(
        means,
        np.full((n, 3), 0.05),
        quats / np.linalg.norm(quats, axis=1, keepdims=True),
        np.full(n, 0.8),
        rng.uniform(-0.5, 0.5, (n, 16, 3)),
        source="gapped",
    )
    return scene, gb.Camera(64, 48, 40.0, 40.0, 32, 24, np.eye(3), np.zeros(3))


def _preprocess_cases():
    yield "gapped", _gapped_scene()
    for seed, sh_degree, filter3d in SCENES[:3]:
        yield f"random{seed}", random_view(seed, n=777, sh_degree=sh_degree, filter3d=filter3d, W=61, H=37)
    yield "needles", _needle_scene(5)
    yield "cuts", _cut_scene(7)
    scene, cam = _cut_scene(7)
    yield "cuts orthographic", (scene, cam.with_projection("orthographic", 2.0))


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
def test_preprocess_bitwise(path, mode):
    """The vector preprocess gives every splat's Splat2D (every field, bit for bit), tile rectangle and culling decision
    exactly as the scalar one, in every mode, SH degree, with 3D filters, view weights, depth correction and cells,
    for perspective and orthographic cameras."""
    for name, (scene, cam) in _preprocess_cases():
        variants = [{}]
        if mode in ("wsr", "duplex"):
            variants.append({"depth_correct": True})
        if mode == "duplex":
            scene = gb.Scene.from_arrays(
                scene.means,
                scene.scales,
                scene.quats,
                scene.opacities,
                scene.sh,
                scene.filter_3d,
                view_weight_sh=scene.oit and scene.oit.view_weight_sh,
                cells=build_cells(scene, 6),
            )
        for kw in variants + [{"sh_degree": 1}, {"sh_degree": 2}]:
            ref, ref_frame = preprocessed("scalar", scene, cam, mode, **kw)
            vec, vec_frame = preprocessed(path, scene, cam, mode, **kw)
            what = f"{path} {mode} {name} {kw}"
            assert ref["valid"].sum() > 0 and (ref["valid"] == 0).sum() > 0, what
            as_bytes = lambda r: r.view(np.uint8).reshape(len(r), -1)  # noqa: E731
            bad = np.flatnonzero((as_bytes(ref) != as_bytes(vec)).any(axis=1))
            if len(bad):
                fields = [f for f in SPLAT2D.names if (ref["splat"][f][bad] != vec["splat"][f][bad]).any()]
                decided = (ref["valid"][bad] != vec["valid"][bad]).sum()
                rects = (ref["rect"][bad] != vec["rect"][bad]).any(axis=1).sum()
                pytest.fail(
                    f"{what}: {len(bad)} splats differ (first {bad[:5]}): {decided} decisions, {rects} "
                    f"rectangles, fields {fields}"
                )
            for stat in ("visible", "sort_length", "pairs"):
                assert getattr(vec_frame.stats, stat) == getattr(ref_frame.stats, stat), what


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("preset", ["spark", "antimatter15"])
def test_preset_rules_preprocess_bitwise(path, preset):
    """The presets' rules (base-colour clamp, support cut, radial depth) keep the vector preprocess the scalar one's,
    bit for bit."""
    for name, (scene, cam) in _preprocess_cases():
        ref, _ = preprocessed("scalar", scene, cam, f"preset:{preset}")
        vec, _ = preprocessed(path, scene, cam, f"preset:{preset}")
        assert ref["valid"].sum() > 0 and ref.tobytes() == vec.tobytes(), f"{path} {preset} {name}"


@pytest.mark.parametrize("path", VECTOR_PATHS)
def test_lod_preprocess_bitwise(path):
    """A level-of-detail frame's preprocess (the stage reads a cut's scattered rows: scene leaves, then hierarchy
    nodes, opacities times the cut's weights) is the scalar path's, bit for bit, with a 3D filter and every SH
    degree."""
    seed = SCENES[2][0]
    scene, cam = random_view(seed, n=3000, sh_degree=3, filter3d=True, W=61, H=37)
    tree = lod.build(scene)  # the hierarchy the renderer draws (the same build; its cache is not needed here)
    for tau in (32.0, 64.0):  # these splats are large against the 61 x 37 image: cuts of 150-200 nodes
        for degree in (3, 2, 0):
            out = []
            for p in ("scalar", path):
                _native.testing.set_capture_preprocess(True)
                try:
                    frame = render(p, scene, cam, "gaussian_blending", lod=tau, sh_degree=degree)
                    out.append(_native.testing.captured_preprocess())
                finally:
                    _native.testing.set_capture_preprocess(False)
            what = f"{path} lod {tau} sh {degree}"
            assert len(lod.cut(tree, cam, tau).nodes) > 100 and frame.stats.lod_splats > 100, what
            assert out[0] == out[1], what


def _needle_scene(seed):
    """Needle-thin, rotated, huge and tiny splats: where the pixel boxes are tightest and float rounding largest."""
    rng = np.random.default_rng(seed)
    n = 400
    means = np.c_[rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n), rng.uniform(2, 6, n)]
    scales = np.exp(rng.uniform(np.log(1e-4), np.log(2.0), (n, 3)))
    scales[: n // 3, 0] = rng.uniform(1.0, 8.0, n // 3)  # long in x, thin in y and z
    scales[: n // 3, 1:] = rng.uniform(1e-5, 1e-3, (n // 3, 2))
    quats = rng.normal(size=(n, 4))
    op = rng.uniform(0.004, 1.0, n)
    sh = rng.uniform(-1, 1, (n, 1, 3))
    cam = gb.Camera(96, 72, 80.0, 70.0, 48.3, 35.7, np.eye(3), np.zeros(3))
    return gb.Scene.from_arrays(means, scales, quats, op, sh), cam


def _small_opaque_scene(seed):
    """Opaque splats of 0.2-1.5 px sigma: their cut-off reach is a few pixels, so a window's own extent decides."""
    rng = np.random.default_rng(seed)
    n = 1500
    z = rng.uniform(2, 4, n)
    means = np.c_[rng.uniform(-1.2, 1.2, n) * z, rng.uniform(-0.9, 0.9, n) * z, z]
    scales = rng.uniform(0.2, 1.5, (n, 3)) * z[:, None] / 40.0
    op = rng.uniform(0.3, 1.0, n)
    cam = gb.Camera(64, 48, 40.0, 40.0, 32.0, 24.0, np.eye(3), np.zeros(3))
    return gb.Scene.from_arrays(means, scales, rng.normal(size=(n, 4)), op, rng.uniform(-1, 1, (n, 1, 3))), cam


@pytest.mark.parametrize("path", ALL_PATHS)
@pytest.mark.parametrize("mode", ["scalar", "mip", "gaussian_blending", "gaussian_blending+fast", "wsr", "duplex"])
@pytest.mark.parametrize("make_scene", [_needle_scene, _small_opaque_scene])
def test_pixel_boxes_change_no_pixel(path, mode, make_scene):
    """Skipping lane groups outside a splat's pixel box (gaussian_blending: outside the group's window box) is exact:
    bit-identical images and evaluation counts."""
    scene, cam = make_scene(5)
    for c in (cam, cam.at_sampling_rate(1 / 2), cam.at_sampling_rate(1 / 4)):
        on = render(path, scene, c, mode, supersample=2)
        _native.testing.set_pixel_boxes(False)
        try:
            off = render(path, scene, c, mode, supersample=2)
        finally:
            _native.testing.set_pixel_boxes(True)
        np.testing.assert_array_equal(on.rgb, off.rgb)
        np.testing.assert_array_equal(on.alpha, off.alpha)
        np.testing.assert_array_equal(on.debug["evals"], off.debug["evals"])


@pytest.mark.parametrize("path", ALL_PATHS)
def test_hostile_splats_no_nan(path):
    """Degenerate splats (zero scales and quaternions), exponents that underflow (faint, far and subnormal-scaled
    splats), non-finite inputs (dropped by the scene with a warning): finite pixels on every path, within the
    vector-vs-scalar tolerance."""
    rng = np.random.default_rng(9)
    n = 300
    means = np.c_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(0.3, 50, n)]
    scales = np.exp(rng.uniform(np.log(1e-30), np.log(3.0), (n, 3)))
    scales[:20] = 0.0
    scales[20:30] = 1e-38  # subnormal squares
    quats = rng.normal(size=(n, 4))
    quats[30:40] = 0.0
    op = np.exp(rng.uniform(np.log(1.0 / 256), 0.0, n))
    op[40:50] = 1.0
    sh = rng.uniform(-1, 1, (n, 1, 3))
    means[50, 0], scales[51, 1], op[52] = np.nan, np.inf, np.nan
    with pytest.warns(UserWarning):
        scene = gb.Scene.from_arrays(means, scales, quats, op, sh)
    cam = gb.Camera(80, 60, 70.0, 70.0, 40.0, 30.0, np.eye(3), np.zeros(3))
    for mode in MODES + ("gaussian_blending+fast",):
        vec = render(path, scene, cam, mode, supersample=2)
        assert np.isfinite(vec.rgb).all() and np.isfinite(vec.alpha).all(), mode
        if path != "scalar":
            assert_close_to_scalar(vec, render("scalar", scene, cam, mode, supersample=2), f"{path} {mode}")


def _python(code: str, simd_env: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("GBVIEWER_SIMD", None)
    if simd_env is not None:
        env["GBVIEWER_SIMD"] = simd_env
    # outside the checkout, so that the installed package (with its built module) is the one imported
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120, cwd=tempfile.gettempdir()
    )


def test_env_var_forces_path():
    res = _python("import gbviewer._native as n; print(n.simd())", "scalar")
    assert res.returncode == 0 and res.stdout.strip() == "scalar", res.stderr
    res = _python("import gbviewer._native as n; print(n.simd())", None)
    assert res.stdout.strip() == _native.simd_paths()[-1]


@pytest.mark.parametrize("value", ["avx9000", "AVX2 ", "avx512"])
def test_env_var_rejects_unknown_or_unsupported(value):
    res = _python("import gbviewer._native", value)
    if value == "avx512" and "avx512" in _native.simd_paths():
        assert res.returncode == 0
        return
    assert res.returncode != 0
    assert f"GBVIEWER_SIMD={value}" in res.stderr and "available here: scalar" in res.stderr
    # the renderer says why the CPU backend is unavailable, without suggesting a reinstall
    res = _python("from gbviewer.render import CpuRenderer; print(CpuRenderer.available())", value)
    assert "GBVIEWER_SIMD" in res.stdout and "reinstall" not in res.stdout


def test_set_simd_and_exp_rate():
    with pytest.raises(ValueError, match="available here"):
        _native.testing.set_simd("sve")
    with pytest.raises(ValueError):
        _native.testing.exp_rate("sve", 1000)
    for path in _native.simd_paths():
        assert _native.testing.exp_rate(path, 100_000) > 0


_EMULATED = r"""
import sys, json, numpy as np, gbviewer as gb
from gbviewer import _native
rng = np.random.default_rng(0); n = 300
scene = gb.Scene.from_arrays(np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 4, n)], np.full((n, 3), 0.05),
                             rng.normal(size=(n, 4)), rng.uniform(0.1, 1, n), rng.uniform(-1, 1, (n, 1, 3)))
cam = gb.Camera(48, 32, 40.0, 40.0, 24.0, 16.0, np.eye(3), np.zeros(3))
out = {"paths": _native.simd_paths()}
for mode in ("scalar", "gaussian_blending", "wsr", "duplex", "analytic"):
    f = gb.render(scene, cam, mode=mode, supersample=2)
    np.save(f"{sys.argv[1]}/{mode}.npy", f.rgb)
    out[mode] = f.stats.simd
print(json.dumps(out))
"""


def emulated_env() -> dict[str, str]:
    """The emulated child's environment without what selects CPU code paths: OPENBLAS_CORETYPE=Haswell (set on some
    hosts) makes numpy's OpenBLAS run AVX2 on the emulated Nehalem and die of SIGILL, NPY_* dispatch variables and
    GBVIEWER_SIMD would force paths the emulated CPU may lack; the child must choose for the CPU it runs on."""
    return {
        k: v for k, v in os.environ.items() if not k.startswith(("OPENBLAS_", "NPY_", "GOTO", "MKL_", "GBVIEWER_SIMD"))
    }


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the x86-64 build's instruction sets")
@pytest.mark.parametrize("cpu, paths", [("Nehalem", ["scalar"]), ("Haswell", ["scalar", "avx2"])])
def test_module_runs_on_an_older_cpu(tmp_path, cpu, paths):
    """The built module on an emulated CPU (qemu-user): a Nehalem (SSE4.2, no AVX) gets the scalar path and no illegal
    instruction (nothing is built for the build machine's CPU), a Haswell gets AVX2; images match this machine's."""
    import json
    import shutil

    qemu = shutil.which("qemu-x86_64")
    if qemu is None:
        skip_or_fail("qemu-x86_64 not installed (Debian: qemu-user)")
    res = subprocess.run(
        [qemu, "-cpu", cpu, sys.executable, "-c", _EMULATED, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tempfile.gettempdir(),
        env=emulated_env(),
    )
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["paths"] == paths
    rng = np.random.default_rng(0)
    n = 300
    scene = gb.Scene.from_arrays(
        np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 4, n)],
        np.full((n, 3), 0.05),
        rng.normal(size=(n, 4)),
        rng.uniform(0.1, 1, n),
        rng.uniform(-1, 1, (n, 1, 3)),
    )
    cam = gb.Camera(48, 32, 40.0, 40.0, 24.0, 16.0, np.eye(3), np.zeros(3))
    for mode in ("scalar", "gaussian_blending", "wsr", "duplex", "analytic"):
        assert out[mode] == paths[-1]
        here = render(paths[-1], scene, cam, mode, supersample=2).rgb
        assert np.abs(np.load(tmp_path / f"{mode}.npy") - here).max() < 1e-5, f"{cpu} {mode}"
