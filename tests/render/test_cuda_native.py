"""The CUDA module's pieces that need no device: its error classification, the buffer growth policy, and the scene
and render argument checks it shares with the CPU module (native/bindings/nb_common.h)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_scene

import gbviewer as gb

try:
    from gbviewer import _native_cuda
except ImportError:
    _native_cuda = None
needs_module = pytest.mark.skipif(_native_cuda is None, reason="gbviewer._native_cuda is not built (no nvcc)")


@needs_module
@pytest.mark.parametrize(
    "code, name, fatal",
    [
        (702, "cudaErrorLaunchTimeout", True),  # the display watchdog
        (700, "cudaErrorIllegalAddress", True),
        (719, "cudaErrorLaunchFailure", True),
        (710, "cudaErrorAssert", True),
        (46, "cudaErrorDevicesUnavailable", True),
        (2, "cudaErrorMemoryAllocation", False),  # out of memory: the device stays usable
        (9, "cudaErrorInvalidConfiguration", False),
        (1, "cudaErrorInvalidValue", False),
    ],
)
def test_error_classification(code, name, fatal):
    """Sticky errors raise DeviceFailed (the renderer unusable) without asking the device; others are asked about
    with a synchronise, and out of memory never is."""
    assert _native_cuda.error_info(code) == (name, fatal)
    assert issubclass(_native_cuda.DeviceFailed, RuntimeError)


@needs_module
def test_first_allocation_is_the_request():
    """4096 x 4096 at supersample 8: the request alone (no 1.5x head room that turns a fitting render into out of
    memory); growth by 1.5x, at least the request."""
    request = (4096 * 8) ** 2 * 3  # floats of the supersampled rgb plane
    assert _native_cuda.grown_capacity(0, request) == request
    assert _native_cuda.grown_capacity(100, 50) == 100
    assert _native_cuda.grown_capacity(100, 101) == 150
    assert _native_cuda.grown_capacity(100, 1000) == 1000


def sh_without_coefficients(n: int = 5) -> tuple:
    s = random_scene(n, seed=1)
    return s.means, s.scales, s.quats, s.opacities, np.zeros((n, 0, 3), np.float32)


@needs_module
def test_cuda_refuses_sh_without_coefficients():
    with pytest.raises(ValueError, match="^upload: sh must hold K >= 1 coefficients"):
        _native_cuda.check_scene(*sh_without_coefficients(), None)
    assert _native_cuda.check_scene(*sh_without_coefficients()[:4], np.zeros((5, 1, 3), np.float32), None) == 5


def test_cpu_refuses_sh_without_coefficients():
    """The same check in the CPU module (it read past the end of the array before)."""
    from gbviewer import _native

    cam = gb.Camera(8, 8, 10, 10, 4, 4, np.eye(3), [0.0, 0.0, 5.0])
    from gbviewer.render.prepare import camera_args

    with pytest.raises(ValueError, match="sh must hold K >= 1 coefficients"):
        _native.Renderer().upload(*sh_without_coefficients(), None)
    r = _native.Renderer()  # a scene with coefficients renders (the check refuses only K = 0)
    r.upload(*sh_without_coefficients()[:4], np.zeros((5, 1, 3), np.float32), None)
    assert r.render(*camera_args(cam), 0, 1, 3, np.zeros(3, np.float32), False)["rgb"].shape == (8, 8, 3)


@needs_module
def test_tall_images_pass_the_checks():
    """Heights past CUDA's 65,535-block grid rows (1,048,560 px) are allowed where the pixel count is: the kernels
    number tiles along one grid dimension (the GPU run is tests/render/test_cuda_gpu.py)."""
    args = dict(
        R=np.eye(3, dtype=np.float32),
        t=np.zeros(3, np.float32),
        fx=60.0,
        fy=60.0,
        cx=1.0,
        cy=24.0,
        width=1,
        height=1_100_000,
        near_plane=0.2,
        projection=0,
        mode=0,
        supersample=1,
        sh_degree=3,
        background=np.zeros(3, np.float32),
    )
    _native_cuda.check_render_args(**args)
    _native_cuda.check_render_args(**dict(args, height=600_000, supersample=2))


@needs_module
def test_cuda_refuses_lod_nodes_that_are_not_finite():
    """upload_lod's checks, shared with the CPU's: upload's shapes, and every value of the nodes finite (the stage
    reads them as scene rows)."""
    tree = gb.lod.build(random_scene(500, seed=4))
    nodes = [tree.means, tree.scales, tree.quats, tree.opacities, tree.sh]
    m = len(tree.means)
    assert _native_cuda.check_lod_nodes(*nodes, None) == m > 0
    assert _native_cuda.check_lod_nodes(*nodes, np.ones(m, np.float32)) == m
    bad_filter = np.ones(m, np.float32)
    bad_filter[-1] = np.inf
    for i in range(len(nodes) + 1):
        args = [a.copy() for a in nodes] + [None]
        if i < len(nodes):
            args[i].flat[args[i].size // 2] = np.nan
        else:
            args[i] = bad_filter
        with pytest.raises(ValueError, match="^upload_lod: the interior arrays hold values that are not finite"):
            _native_cuda.check_lod_nodes(*args)
    with pytest.raises(ValueError, match="^upload_lod: array shapes do not match"):
        _native_cuda.check_lod_nodes(*nodes[:4], tree.sh[:-1], None)


@needs_module
def test_the_wrapper_finds_its_native_calls():
    """The names gbviewer/render/cuda.py and the GPU tests call exist in the built module (a stand-in answers them
    without a GPU)."""
    for name in (
        "upload",
        "upload_weights",
        "upload_cells",
        "upload_lod",
        "upload_cut",
        "render",
        "render_to_gl_texture",
        "release_gl_texture",
        "release_buffers",
    ):
        assert callable(getattr(_native_cuda.Renderer, name, None)), name
    assert callable(_native_cuda.memory_info)
