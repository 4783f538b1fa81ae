"""gaussian_blending's fast precision on the glsl backend (blend.comp's GB_FAST variant: blend.glsl's port of
blend_gaussian's Fast), on llvmpipe here: test_gb_fast.py's bound against the backend's own exact frames on every
shared scene and on generated scenes at x8 .. x1/8, its fast frames against the CPU's within the tolerances the exact
ones meet (glsl_helpers.compare), and FrameStats naming the precision that ran."""

from __future__ import annotations

import numpy as np
import pytest
from glsl_helpers import awkward_scene, compare
from helpers import front_camera, shared_scene
from hypothesis import HealthCheck, given, settings
from test_gb_fast import (
    EXACT,
    FAST,
    GENERATED,
    RATES,
    SCENES,
    check_bound,
    check_generated,
)

import gbviewer as gb
from gbviewer.render import create_renderer

pytestmark = pytest.mark.gl


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_glsl_fast_within_bound_on_shared_scenes(gl, name):
    """Every rate through one upload (on llvmpipe a large scene's upload and stage cost more than the blend)."""
    scene = gb.load(shared_scene(name))
    r = create_renderer("glsl")
    r.upload(scene)
    for rate in RATES:
        cam = gb.orbit_camera(scene, 30, 20, width=40, height=30).at_sampling_rate(rate)
        check_bound(scene, cam, f"glsl {name} x{rate:g}", renderer=r)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(**GENERATED)
def test_glsl_fast_within_bound_on_generated_scenes(gl, n, seed, log_scale, rate, layered):
    check_generated(n, seed, log_scale, rate, layered, "glsl")


@pytest.mark.parametrize("name", ["plant.splat", "biker.compressed.ply"])
def test_glsl_fast_matches_cpu_fast(gl, name):
    scene = gb.load(shared_scene(name))
    cam = gb.orbit_camera(scene, 40, 25, width=64, height=48)
    for c in (cam, cam.at_sampling_rate(1 / 4), cam.at_sampling_rate(4)):
        compare(scene, c, "gaussian_blending+fast")


@pytest.mark.parametrize("seed, filter3d", [(1, False), (2, True)])
@pytest.mark.parametrize("spec", ["gaussian_blending+fast", "gaussian_blending:3+fast"])
def test_glsl_fast_matches_cpu_fast_on_awkward_scenes(gl, seed, filter3d, spec):
    compare(awkward_scene(seed, filter3d=filter3d), front_camera(64, 48), spec, background=(1.0, 1.0, 1.0))


def test_glsl_frame_says_its_precision(gl):
    scene = gb.load(shared_scene("plant.splat"))
    cam = gb.orbit_camera(scene, 30, 20, width=64, height=48)
    r = create_renderer("glsl")
    r.upload(scene)
    fast, exact = r.render(cam, FAST), r.render(cam, EXACT)
    assert (fast.stats.backend, fast.stats.precision, exact.stats.precision) == ("glsl", "fast", "exact")
    assert fast.stats.mode == "gaussian_blending fast" and exact.stats.mode == "gaussian_blending"
    assert not np.array_equal(fast.rgb, exact.rgb)  # another kernel ran
    assert r.render(cam, gb.RenderSettings.parse("scalar+fast")).stats.precision == "exact"
