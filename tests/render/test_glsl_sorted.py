"""The glsl backend's per-pixel sorted modes (eval3d, stopthepop: shaders/ray3d.glsl, resort.glsl, blend.comp's
sorted walk) against the CPU backend, with glsl_helpers' tolerances, on awkward scenes small enough for llvmpipe's
loop cap; the cap's refusal in one line where the lists are too long (the sorted walk runs in one dispatch)."""

from __future__ import annotations

import numpy as np
import pytest
from glsl_helpers import awkward_scene, compare
from helpers import front_camera
from test_stopthepop import camera, crossing_splats
from test_stopthepop_hier import late_near_splat

import gbviewer as gb
from gbviewer.core.errors import RenderError
from gbviewer.render import RenderSettings
from gbviewer.render.glsl import limits

pytestmark = pytest.mark.gl

SPECS = ["eval3d", "stopthepop", "stopthepop:0", "stopthepop:1", "stopthepop:16", "eval3d:2", "stopthepop:4:2"]


@pytest.mark.parametrize("seed, filter3d", [(1, False), (2, True)])
@pytest.mark.parametrize("spec", SPECS)
def test_sorted_modes_match_the_cpu(gl, seed, filter3d, spec):
    compare(awkward_scene(seed, n=300, filter3d=filter3d), front_camera(64, 48), spec, background=(1.0, 1.0, 1.0))


@pytest.mark.parametrize("spec", ["eval3d", "stopthepop"])
def test_orthographic(gl, spec):
    scene = awkward_scene(3, n=300)
    cam = gb.Camera(64, 48, 20.0, 20.0, 32, 24, front_camera().R, front_camera().t, projection="orthographic")
    compare(scene, cam, spec)


def test_loop_cap_refuses_lists_too_long_for_one_dispatch():
    assert limits.plan_sorted(2, 300, None, 0) == [(0, 4, 0, limits.FULL)]
    assert limits.plan_sorted(1, 300, 65535, 4) == [(0, 1, 0, limits.FULL)]
    with pytest.raises(RenderError, match="per-pixel sorted frame with tile lists of 300 splats .* use the cpu"):
        limits.plan_sorted(1, 300, 65535, 0)
    with pytest.raises(RenderError, match="65535"):
        limits.plan_sorted(4, 4000, 65535, 4)


@pytest.mark.parametrize("scene_fn, pixel", [(lambda: crossing_splats(0.002), (24, 20)), (late_near_splat, (28, 20))])
def test_hierarchy_pixels_match_the_cpu(gl, scene_fn, pixel):
    """stopthepop's constructed pixels (test_stopthepop_hier.py): the tile stage's sort (tile_keys.comp), the 4x4
    and 2x2 queues and the pixel's as on the CPU, where each of them changes the pixel."""
    scene, cam = scene_fn(), camera()
    compare(scene, cam, "stopthepop")
    cpu = gb.get_renderer(scene, "cpu").render(cam, RenderSettings.parse("stopthepop")).rgb
    out = gb.get_renderer(scene, "glsl").render(cam, RenderSettings.parse("stopthepop")).rgb
    x, y = pixel
    assert np.abs(out[y, x] - cpu[y, x]).max() < 1e-4
