"""CUDA fixes that only a GPU can run (they skip elsewhere, saying why; bench/gpu_session.sh runs them): images
taller than CUDA's grid rows, uploads of other scenes racing cell uploads, a large cell of splats at one depth
(the canonical order's former quadratic case), the caller's current device left alone (and no context made on
device 0 for a thread that never chose it), release() freeing the device memory, the per-pixel sorted modes
(eval3d, stopthepop) as on the CPU, and gaussian_blending's fast precision (test_gb_fast.py's bound, as on the CPU)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from helpers import front_camera, random_scene, run_threads, shared_scene
from hypothesis import HealthCheck, given, settings
from test_gb_fast import FAST, GENERATED, RATES, check_bound, check_generated

import gbviewer as gb
from gbviewer.model.cells import Cells, build_cells
from gbviewer.render import CudaRenderer

CUDA_OK, CUDA_WHY = CudaRenderer.available()
pytestmark = pytest.mark.skipif(not CUDA_OK, reason=f"no CUDA runtime here: {CUDA_WHY}")


def close(a: gb.Frame, b: gb.Frame) -> None:
    d = np.abs(a.rgb - b.rgb).max(axis=2)
    assert d.mean() < 1e-4 and (d > 1 / 255).mean() < 0.002, (d.mean(), d.max())
    assert (a.stats.visible, a.stats.pairs) == (b.stats.visible, b.stats.pairs)


@pytest.mark.parametrize("supersample", [1, 2])
def test_cuda_renders_images_taller_than_the_grid_rows(supersample):
    """1,050,000 rows (65,625 tile rows, past the 65,535 a grid's y dimension holds) render as on the CPU."""
    height = 1_050_000 // supersample
    cam = gb.Camera(2, height, 60, 60, 1, height / 2, np.eye(3), np.zeros(3))
    scene = random_scene(300, seed=7, spread=0.05)
    close(
        gb.render(scene, cam, "scalar", supersample=supersample, backend="cuda"),
        gb.render(scene, cam, "scalar", supersample=supersample, backend="cpu"),
    )


def test_cuda_cell_uploads_racing_scene_uploads():
    """Two threads upload scenes of other sizes and their cells into one renderer: a cell upload checked against
    a scene that another thread replaced meanwhile is refused (never copied past an array); the last consistent
    upload renders as the CPU."""
    from gbviewer import _native_cuda

    native = _native_cuda.Renderer()
    scenes = [random_scene(n, seed=n) for n in (50, 3000)]
    cells = [build_cells(s, 8) for s in scenes]

    def work(i: int) -> None:
        s, c = scenes[i], cells[i]
        for _ in range(40):
            native.upload(s.means, s.scales, s.quats, s.opacities, s.sh, None)
            try:
                native.upload_cells(c.means, c.scales, c.quats, c.offsets, c.members, c.cell_of(s.num_splats))
            except (RuntimeError, ValueError) as exc:
                assert "another scene" in str(exc) or "partition" in str(exc) or "cell_of" in str(exc), exc

    run_threads(work, 2, timeout=120)
    scene = gb.Scene.from_arrays(
        scenes[1].means, scenes[1].scales, scenes[1].quats, scenes[1].opacities, scenes[1].sh, cells=cells[1]
    )
    close(
        gb.render(scene, front_camera(), "duplex", backend="cuda"),
        gb.render(scene, front_camera(), "duplex", backend="cpu"),
    )


def test_cuda_duplex_large_cell_at_one_depth():
    """20,000 camera-facing splats at one depth in one cell (one run of equal depth, which the former kernel ranked
    in O(run^2)): the image does not depend on the members' order and matches the CPU's, counts exactly."""
    n = 20_000
    rng = np.random.default_rng(9)
    means = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.full(n, 3.0)], 1)
    scales = np.stack([np.full(n, 0.02), np.full(n, 0.02), np.full(n, 1e-4)], 1)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    sh = rng.normal(0, 0.5, (n, 1, 3))
    base = gb.Scene.from_arrays(means, scales, quats, rng.uniform(0.2, 0.9, n), sh)
    members = np.arange(n, dtype=np.int32)

    def one(m):
        return Cells(
            np.float32([[0, 0, 3]]), np.float32([[1, 1, 0.01]]), np.float32([[1, 0, 0, 0]]), np.int32([0, n]), m
        )

    cam = front_camera(128, 96)
    frames = []
    for m in (members, rng.permutation(members).astype(np.int32)):
        scene = gb.Scene.from_arrays(base.means, base.scales, base.quats, base.opacities, base.sh, cells=one(m))
        frames.append(gb.render(scene, cam, "duplex", backend="cuda"))
    assert np.array_equal(frames[0].rgb, frames[1].rgb)
    close(frames[0], gb.render(scene, cam, "duplex", backend="cpu"))


def test_cuda_renderer_leaves_the_callers_device_current():
    """A renderer on another device than the one a thread chose restores the thread's device after each call."""
    from gbviewer import _native_cuda

    try:
        native = _native_cuda.Renderer(1)
    except RuntimeError as exc:
        pytest.skip(f"one CUDA device only: {exc}")
    chosen = []

    def work(_: int) -> None:
        _native_cuda.Renderer(0)  # this thread now has device 0 current
        s = random_scene(20)
        native.upload(s.means, s.scales, s.quats, s.opacities, s.sh, None)
        chosen.append(_native_cuda.default_device())

    run_threads(work, 1, timeout=60)
    assert native.device == 1 and chosen == [0]


PRIMARY_CONTEXT_ACTIVE = """
import ctypes
cuda = ctypes.CDLL("libcuda.so.1")
def active(device):
    dev, flags, on = ctypes.c_int(), ctypes.c_uint(), ctypes.c_int()
    assert cuda.cuInit(0) == 0 and cuda.cuDeviceGet(ctypes.byref(dev), device) == 0
    assert cuda.cuDevicePrimaryCtxGetState(dev, ctypes.byref(flags), ctypes.byref(on)) == 0
    return bool(on.value)
"""


def test_cuda_renderer_makes_no_context_on_device_0():
    """A process whose threads never chose a device renders on device 1 only: the guard no longer 'restores'
    device 0 after each call (which created a context there, memory on GPU 0 and, on an exclusive-process GPU 0
    held by another process, an error pinned on device 1)."""
    script = PRIMARY_CONTEXT_ACTIVE + textwrap.dedent("""
        import threading
        import numpy as np
        from gbviewer import _native_cuda
        native = _native_cuda.Renderer(1)
        z = np.zeros((4, 3), np.float32)
        q = np.tile(np.float32([1, 0, 0, 0]), (4, 1))
        def call():
            native.upload(z, z + 0.1, q, np.full(4, 0.5, np.float32), np.zeros((4, 1, 3), np.float32), None)
        call()
        t = threading.Thread(target=call)
        t.start()
        t.join()
        print(active(0), active(1))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    if "does not exist" in proc.stderr:
        pytest.skip("one CUDA device only")
    assert proc.returncode == 0 and proc.stdout.split() == ["False", "True"], proc.stdout + proc.stderr[-2000:]


def test_cuda_release_frees_the_device_memory():
    """CudaRenderer.release() gives back the scene's and the frame's device buffers (it freed nothing: several GB
    held at 6 M splats); the next frame uploads the scene again and renders as before."""
    from gbviewer import _native_cuda

    n = 1_000_000
    scene = random_scene(n, seed=3)
    scene_bytes = sum(a.nbytes for a in (scene.means, scene.scales, scene.quats, scene.opacities, scene.sh))
    r = CudaRenderer()
    device = r._impl.device
    cam = front_camera(640, 480)
    r.upload(scene)
    first = r.render(cam, gb.RenderSettings("gaussian_blending"))
    held = _native_cuda.memory_info(device)[0]
    r.release()
    freed = _native_cuda.memory_info(device)[0] - held
    assert freed >= scene_bytes, (freed, scene_bytes)
    r.upload(scene)
    again = r.render(cam, gb.RenderSettings("gaussian_blending"))
    close(first, again)


@pytest.mark.parametrize(
    "spec", ["eval3d", "eval3d:2", "stopthepop", "stopthepop:0", "stopthepop:1", "stopthepop:16:2"]
)
def test_cuda_sorted_modes_render_as_on_the_cpu(spec):
    """The same fragments and order rules (gbv/ray3d.h, gbv/resort.h; the exact order by selection on the GPU, by a
    stable sort on the CPU): the CPU's image up to the exp's last bits, with every awkward kind of splat."""
    from helpers import random_view

    scene, cam = random_view(5, n=300, W=61, H=37)
    close(gb.render(scene, cam, spec, backend="cuda"), gb.render(scene, cam, spec, backend="cpu"))


def test_cuda_stopthepop_hierarchy_pixel_as_on_the_cpu():
    """The pixel the published hierarchy blends out of order (test_stopthepop_hier.late_near_splat: the tile stage's
    sort in bin_splats, the 4x4 and 2x2 queues) as on the CPU."""
    from test_stopthepop import camera
    from test_stopthepop_hier import late_near_splat

    scene, cam = late_near_splat(), camera()
    a, b = gb.render(scene, cam, "stopthepop", backend="cuda"), gb.render(scene, cam, "stopthepop", backend="cpu")
    close(a, b)
    assert np.abs(a.rgb[20, 28] - b.rgb[20, 28]).max() < 1e-4


@pytest.mark.parametrize("name", ["plant.splat", "biker.compressed.ply", "st-peter.sog"])
def test_cuda_fast_gaussian_blending(name):
    """render_kernel's Fast (the one-pixel blend_gaussian's): within 1/1024 of CUDA's exact frames at x8 .. x1/8, as
    close to the CPU's fast frames as the exact ones are, and FrameStats saying which precision ran."""
    scene = gb.load(shared_scene(name))
    r = CudaRenderer()
    r.upload(scene)
    for rate in RATES:
        cam = gb.orbit_camera(scene, 30, 20, width=80, height=60).at_sampling_rate(rate)
        check_bound(scene, cam, f"cuda {name} x{rate:g}", renderer=r)
        fast = r.render(cam, FAST)
        close(fast, gb.render(scene, cam, FAST.spec, backend="cpu"))
        assert (fast.stats.precision, fast.stats.mode) == ("fast", "gaussian_blending fast")


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(**GENERATED)
def test_cuda_fast_within_bound_on_generated_scenes(n, seed, log_scale, rate, layered):
    check_generated(n, seed, log_scale, rate, layered, "cuda")
