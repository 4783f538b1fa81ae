"""CUDA backend: the module must build wherever nvcc exists; its argument checks and the Python wrapper's state
handling run without a GPU; runtime comparisons with the CPU backend run only where a CUDA device is present (they
skip, saying why, elsewhere).

Exactness on a GPU: `visible` and `pairs` (tile-list entries) must equal the CPU's. The preprocess decisions are
bit-identical on every backend (products rounded through mul_rn, tests/render/test_fp_contract.py), and duplex orders
each cell's splats canonically on both (gbv/order.h), so the only float differences left are in the blend (fused
multiply-adds, device expf/logf), bounded per image below."""

from __future__ import annotations

import importlib
import shutil

import numpy as np
import pytest
from helpers import front_camera, random_scene, shared_scene
from test_render import check_concurrent_renders

import gbviewer as gb
from gbviewer.model.cells import Cells, build_cells
from gbviewer.render import CudaRenderer

MODES = ["scalar", "mip", "analytic", "gaussian_blending", "wsr", "duplex"]
CUDA_OK, CUDA_WHY = CudaRenderer.available()
needs_gpu = pytest.mark.skipif(not CUDA_OK, reason=f"no CUDA runtime here: {CUDA_WHY}")
try:
    from gbviewer import _native_cuda
except ImportError:
    _native_cuda = None
needs_module = pytest.mark.skipif(_native_cuda is None, reason="gbviewer._native_cuda is not built (no nvcc)")


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="no nvcc on PATH: the CUDA module is not built")
def test_cuda_module_is_built_when_nvcc_exists():
    module = importlib.import_module("gbviewer._native_cuda")
    ok, reason = module.availability()
    assert isinstance(ok, bool) and isinstance(reason, str) and (ok or reason)


@pytest.mark.skipif(CUDA_OK, reason="a CUDA device is present")
def test_unavailable_backend_says_why():
    scene = random_scene(10)
    with pytest.raises(gb.BackendUnavailable, match="cuda backend unavailable: .+"):
        gb.render(scene, front_camera(), "scalar", backend="cuda")


def compare(a: gb.Frame, b: gb.Frame) -> tuple[float, float, float]:
    """Mean and max abs rgb difference, and the fraction of pixels above 1/255."""
    d = np.abs(a.rgb - b.rgb).max(axis=2)
    return float(d.mean()), float(d.max()), float((d > 1 / 255).mean())


@needs_gpu
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("scene_name", ["bundled", "v3dg-donut.fused.ply", "random"])
def test_cuda_matches_cpu(mode, supersample, scene_name):
    if scene_name == "bundled":
        scene = gb.load(gb.DEFAULT_SCENE)
    elif scene_name == "random":
        scene = random_scene(300, seed=3, sh_degree=3)
    else:
        scene = gb.load(shared_scene(scene_name))
    cam = front_camera(160, 120) if scene_name == "random" else gb.orbit_camera(scene, 40, 15, width=320, height=240)
    cpu = gb.render(scene, cam, mode, supersample=supersample, backend="cpu")
    gpu = gb.render(scene, cam, mode, supersample=supersample, backend="cuda")
    mean, worst, frac = compare(cpu, gpu)
    assert np.isfinite(gpu.rgb).all()
    # Same headers, same float32 math; fused multiply-adds and device expf/erff differ in the last bits, which can
    # flip a 1/255 or early-termination decision on a few pixels.
    assert mean < 1e-4 and frac < 0.002, (mean, worst, frac)
    assert gpu.stats.visible == cpu.stats.visible
    assert gpu.stats.pairs == cpu.stats.pairs  # sort_length: the cpu sorts one key per splat, the gpu per pair


@needs_gpu
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("supersample", [1, 2])
def test_cuda_orthographic_matches_cpu(mode, supersample):
    """An orthographic orbit (and its x1/4 zoom-out) with the tolerances and exact counts above."""
    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 40, 15, width=320, height=240, projection="orthographic")
    for c in (cam, cam.at_sampling_rate(1 / 4)):
        cpu = gb.render(scene, c, mode, supersample=supersample, backend="cpu")
        gpu = gb.render(scene, c, mode, supersample=supersample, backend="cuda")
        mean, worst, frac = compare(cpu, gpu)
        assert mean < 1e-4 and frac < 0.002, (mean, worst, frac)
        assert (gpu.stats.visible, gpu.stats.pairs) == (cpu.stats.visible, cpu.stats.pairs)


@needs_gpu
def test_cuda_buffers_grow_for_larger_scenes():
    cam = front_camera(64, 48)
    r = gb.get_renderer(random_scene(20, seed=1), "cuda")
    r.render(cam, gb.RenderSettings())
    big = random_scene(5000, seed=2)
    r.upload(big)
    f = r.render(cam.at_sampling_rate(4), gb.RenderSettings(gb.Mode.GAUSSIAN_BLENDING))
    ref = gb.render(big, cam.at_sampling_rate(4), "gaussian_blending")
    assert compare(f, ref)[0] < 1e-4


@needs_gpu
def test_cuda_concurrent_renders():
    """Two Python threads share the process's CUDA renderer (every mode, duplex cells uploaded while the other
    thread renders): frames equal the same renders done alone, bit for bit."""
    check_concurrent_renders("cuda", random_scene(400, seed=5, sh_degree=1))


def duplex_scene_with_ties(seed: int = 52) -> tuple[gb.Scene, Cells, int]:
    """Random splats plus a copy of each with other colours (same depth, position, shape: splat_less orders such
    pairs by colour), in cells of 6; returns the scene, its cells and the number of same-depth pairs in a cell."""
    base = random_scene(150, seed=seed, sh_degree=3)
    rng = np.random.default_rng(seed)
    cat = lambda a: np.concatenate([a, a])  # noqa: E731
    sh = np.concatenate([base.sh, rng.normal(0, 0.5, base.sh.shape)])
    scene = gb.Scene.from_arrays(cat(base.means), cat(base.scales), cat(base.quats), cat(base.opacities), sh)
    cells = build_cells(scene, 6)
    ties = 0
    for c in range(cells.num_cells):
        z = scene.means[cells.members[cells.offsets[c] : cells.offsets[c + 1]], 2]
        ties += len(z) - len(np.unique(z))
    scene = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=cells)
    return scene, cells, ties


@needs_gpu
def test_cuda_duplex_order_inside_cells_is_canonical():
    """Permuting the members of every cell leaves the CUDA image unchanged bit for bit (the CPU's canonical order,
    gbv/order.h, splats of equal depth included), and equal to the CPU's up to blend rounding, counts exactly."""
    scene, cells, ties = duplex_scene_with_ties()
    assert ties > 20, ties
    cam = front_camera(96, 72)
    a = gb.render(scene, cam, "duplex", backend="cuda")
    cpu = gb.render(scene, cam, "duplex", backend="cpu")
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        members = cells.members.copy()
        for c in range(cells.num_cells):
            lo, hi = cells.offsets[c], cells.offsets[c + 1]
            members[lo:hi] = rng.permutation(members[lo:hi])
        shuffled = Cells(cells.means, cells.scales, cells.quats, cells.offsets, members)
        other = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=shuffled)
        b = gb.render(other, cam, "duplex", backend="cuda")
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha), f"member permutation {seed}"
    mean, worst, frac = compare(cpu, a)
    assert mean < 1e-4 and frac < 0.002, (mean, worst, frac)
    for key in ("visible", "sort_length", "pairs", "cells_visible", "cell_misses"):
        assert getattr(a.stats, key) == getattr(cpu.stats, key), key


@needs_gpu
@pytest.mark.parametrize("mode", MODES)
def test_cuda_empty_frame(mode):
    """Every splat behind the camera: the background, no evaluations."""
    cam = gb.Camera(32, 32, 30, 30, 16, 16, np.eye(3), [0.0, 0.0, -10.0])
    f = gb.render(random_scene(50), cam, mode, backend="cuda", background=(0.5, 0.25, 1.0))
    assert f.stats.visible == 0 and f.stats.sort_length == 0 and f.stats.pairs == 0
    np.testing.assert_array_equal(f.rgb, np.broadcast_to(np.float32([0.5, 0.25, 1.0]), (32, 32, 3)))
    assert (f.alpha == 0).all() and (f.debug["evals"] == 0).all()


@needs_gpu
def test_cuda_renderer_device():
    r = CudaRenderer()
    assert 0 <= r._impl.device
    with pytest.raises(gb.BackendUnavailable, match="does not exist"):
        CudaRenderer(device=1 << 20)


# ---- without a GPU: argument checks (gbviewer._native_cuda.check_render_args runs Renderer.render's) -------------

GOOD = dict(
    R=np.eye(3, dtype=np.float32),
    t=np.zeros(3, np.float32),
    fx=60.0,
    fy=60.0,
    cx=32.0,
    cy=24.0,
    width=64,
    height=48,
    near_plane=0.2,
    projection=0,
    mode=0,
    supersample=1,
    sh_degree=3,
    background=np.zeros(3, np.float32),
    want_window=False,
    sigma=10.0,
    weight_background=1.0,
    et_grade=4.0,
    depth_correct=False,
)
DUPLEX, WSR = int(gb.Mode.DUPLEX), int(gb.Mode.WSR)
# (changed arguments, message)
BAD_ARGS = [
    (dict(R=np.eye(2, dtype=np.float32)), "R must be 3x3"),
    (dict(background=np.zeros(2, np.float32)), "background 3 floats"),
    (dict(mode=len(gb.Mode)), "unknown mode"),  # one past the last
    (dict(mode=-1), "unknown mode"),
    (dict(supersample=0), "supersample must be 1..8"),
    (dict(supersample=9), "supersample must be 1..8"),
    (dict(mode=DUPLEX, et_grade=0.0), "et_grade must be"),
    (dict(mode=DUPLEX, et_grade=-1.0), "et_grade must be"),
    (dict(mode=DUPLEX, et_grade=float("nan")), "et_grade must be"),
    (dict(mode=DUPLEX, et_grade=float("inf")), "et_grade must be"),
    (dict(R=np.full((3, 3), np.nan, np.float32)), "must be finite"),
    (dict(t=np.float32([0, np.inf, 0])), "must be finite"),
    (dict(background=np.float32([0, 0, np.nan])), "must be finite"),
    (dict(width=0), "width and height"),
    (dict(height=-3), "width and height"),
    (dict(width=16384, height=16384, supersample=8), "2\\^31"),
    (dict(fx=0.0), "fx, fy and near_plane"),
    (dict(fy=float("nan")), "fx, fy and near_plane"),
    (dict(cx=float("inf")), "cx and cy finite"),
    (dict(near_plane=0.0), "fx, fy and near_plane"),
    (dict(projection=2), "projection must be 0 \\(perspective\\) or 1 \\(orthographic\\)"),
    (dict(projection=-1), "projection must be"),
    (dict(mode=WSR, weight_background=-0.5), "weight_background"),
    (dict(mode=DUPLEX, weight_background=float("nan")), "weight_background"),
    (dict(mode=WSR, depth_correct=True, sigma=0.0), "sigma must be"),
]


@needs_module
@pytest.mark.parametrize("changes, message", BAD_ARGS, ids=[f"{i}" for i in range(len(BAD_ARGS))])
def test_cuda_binding_rejects_bad_render_args(changes, message):
    _native_cuda.check_render_args(**GOOD)  # the baseline passes
    with pytest.raises(ValueError, match=f"^render: .*{message}"):
        _native_cuda.check_render_args(**dict(GOOD, **changes))


@needs_module
@pytest.mark.parametrize(
    "changes",
    [
        dict(mode=0, et_grade=0.0),
        dict(mode=DUPLEX),
        dict(mode=WSR, sigma=0.0),
        dict(width=1, height=1, supersample=8),
        dict(cx=-1e6, cy=1e6),
        dict(projection=1),
    ],
)
def test_cuda_binding_accepts_unused_or_odd_args(changes):
    """et_grade matters for duplex only, sigma with depth correction only; off-image principal points are fine."""
    _native_cuda.check_render_args(**dict(GOOD, **changes))


@pytest.mark.parametrize("changes, message", BAD_ARGS)
def test_cpu_binding_rejects_bad_render_args(changes, message):
    """The CPU module parses its arguments with the same helper (nb_common.h's parse_render_args)."""
    from gbviewer import _native

    scene = random_scene(12, seed=3)
    cells = build_cells(scene, 4)
    args = dict(GOOD, **changes)
    r = _native.Renderer()
    r.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, None)
    r.upload_cells(cells.means, cells.scales, cells.quats, cells.offsets, cells.members, cells.cell_of(12))
    with pytest.raises(ValueError, match=f"^render: .*{message}"):
        r.render(**args)
