"""Shared by the CPU SIMD path tests (test_simd*.py, and the tests that run their checks on every path): selecting a
path, rendering on it, the vector-vs-scalar tolerance, the preprocess capture, and scenes at the pixel boxes' edges.

Tolerance between a vector path and the scalar path: the vector exp (Highway, 1 ulp) and libm's expf differ by up to
1 ulp, and FMA contraction differs, so colours and alphas agree to ~1e-6 (asserted: 1e-5) except where an alpha within
~1e-6 of the 1/255 (1/256) cut, or a transmittance that close to the 1e-4 stop, is decided the other way. One flipped
decision costs up to ~alpha x colour (< 2e-2, as in test_render_reference's ties) in that pixel (and, in Gaussian
Blending, a slightly different window for later splats there). Such pixels are counted: at most FLIP_FRACTION of an
image's pixels plus 2. Visible splats, sort lengths and tile-list entries are identical (preprocess is shared).
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest

import gbviewer as gb
from gbviewer import _native
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
