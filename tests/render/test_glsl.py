"""The glsl backend against the CPU backend (the tolerances of glsl_helpers.py) and the float64 reference: the bundled,
shared, random and awkward scenes, orthographic cameras, odd sizes, long tile lists, the split blend, the
order-independent modes' options and the debug planes."""

from __future__ import annotations

import numpy as np
import pytest
from glsl_helpers import MODES, awkward_scene, compare
from helpers import front_camera, random_view, shared_scene
from reference import MODES as REFERENCE_MODES
from test_render_reference import BACKGROUND, SCENES, _check_strict

import gbviewer as gb
from gbviewer.render import RenderSettings
from gbviewer.render.glsl import GlslRenderer, limits

pytestmark = pytest.mark.gl


@pytest.mark.parametrize("spec", MODES)
def test_bundled_scene(gl, bundled_scene, spec):
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=128, height=96)
    compare(bundled_scene, cam, spec, background=(0.2, 0.3, 0.4))


SHARED = ["v3dg-donut.fused.ply", "angel.compressed.ply", "biker.spz"]


@pytest.fixture(scope="module")
def shared_scenes():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = gb.load(shared_scene(name))
        return cache[name]

    return get


@pytest.mark.parametrize("name", SHARED)
@pytest.mark.parametrize("spec", MODES)
def test_shared_scenes(gl, shared_scenes, name, spec):
    scene = shared_scenes(name)
    compare(scene, gb.orbit_camera(scene, 45, 15, width=128, height=96), spec)


@pytest.mark.parametrize("seed, filter3d", [(1, False), (2, True)])
@pytest.mark.parametrize("spec", MODES + ["scalar:3", "analytic:3", "gaussian_blending:3"])
def test_random_scenes(gl, seed, filter3d, spec):
    scene = awkward_scene(seed, filter3d=filter3d)
    compare(scene, front_camera(64, 48), spec, background=(1.0, 1.0, 1.0))


@pytest.mark.parametrize("spec", MODES)
def test_orthographic_cameras(gl, bundled_scene, spec):
    """Orthographic cameras: the bundled scene's orthographic orbit, and the awkward scene seen orthographically."""
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=128, height=96, projection="orthographic")
    compare(bundled_scene, cam, spec, background=(0.2, 0.3, 0.4))
    compare(awkward_scene(4), front_camera(64, 48).with_projection("orthographic", 4.0), spec)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("mode", REFERENCE_MODES)
@pytest.mark.parametrize("seed,sh_degree,filter3d", SCENES[1:3])
def test_orthographic_matches_reference(gl, mode, supersample, seed, sh_degree, filter3d):
    """The GLSL backend against the float64 reference directly, with test_render_reference.py's strict tolerance
    (measured: <= 5e-6 off ties in every mode, as in perspective)."""
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d, projection="orthographic")
    frame = gb.get_renderer(scene, "glsl").render(cam, RenderSettings(gb.Mode.parse(mode), supersample, BACKGROUND))
    _check_strict(frame, scene, cam, mode, supersample)


def test_odd_sizes_and_off_centre(gl):
    """Image sizes that are not multiples of 16 (partial tiles, N=3 blocks past the tile grid), fx != fy."""
    scene = awkward_scene(3)
    cam = gb.Camera(37, 29, 40.0, 33.0, 15.2, 16.9, np.eye(3), np.zeros(3))
    for spec in ("scalar", "gaussian_blending", "mip:3", "gaussian_blending:5"):
        compare(scene, cam, spec)


def test_long_tile_lists(gl):
    """One tile with a list longer than llvmpipe's 65535 loop iterations per invocation: every splat is evaluated
    (the blend is split over dispatches there), as on the CPU. Faint sub-pixel splats, so most pixels never
    terminate."""
    rng = np.random.default_rng(7)
    n = 70_000
    means = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(2.0, 3.0, n)], 1)
    scene = gb.Scene.from_arrays(
        means,
        np.full((n, 3), 0.002),
        rng.normal(size=(n, 4)),
        rng.uniform(0.01, 0.3, n),
        rng.uniform(-1, 1, (n, 1, 3)),
        source="long lists",
    )
    cam = front_camera(16, 16, 30.0)
    compare(scene, cam, "scalar")
    out = gb.get_renderer(scene, "glsl").render(cam, RenderSettings.parse("scalar"))
    ref = gb.get_renderer(scene, "cpu").render(cam, RenderSettings.parse("scalar"))
    assert out.stats.sort_length == out.stats.visible > 65535
    assert out.debug["evals"].max() == out.stats.sort_length
    np.testing.assert_array_equal(out.debug["evals"], ref.debug["evals"])


@pytest.mark.parametrize(
    "spec", ["scalar", "gaussian_blending", "analytic:2", "gaussian_blending:3", "wsr", "duplex:2"]
)
def test_blend_split_over_dispatches(gl, monkeypatch, spec):
    """The multi-dispatch blend (groups of render tiles, windows of the lists, state kept in buffers) that drivers
    with a loop cap need, forced here with a cap of 2000 iterations (lists of 768 splats per dispatch)."""
    renderer = GlslRenderer()
    monkeypatch.setitem(limits._loop_limits, renderer.ctx, 2000)
    assert len(limits.plan_blend(3, 5000, 2000)) == 9 * 7
    scene = awkward_scene(8, n=6000)
    renderer.upload(scene)
    compare(scene, front_camera(48, 32), spec, renderer=renderer)
    renderer.release()


def test_order_independent_options(gl):
    """wsr and duplex with trained view weights, depth correction, other E and cell sizes, supersampling; the GLSL
    backend sums the weights in float in list order, the CPU in fixed point (same values to ~1e-7)."""
    base = awkward_scene(9, n=2000)
    rng = np.random.default_rng(9)
    vw = rng.normal(0.0, 0.3, (base.num_splats, 9))
    vw[:, 0] = rng.uniform(-0.3, 3.0, base.num_splats)
    scene = gb.Scene.from_arrays(
        base.means,
        base.scales,
        base.quats,
        base.opacities,
        base.sh,
        view_weight_sh=vw,
        wsr_sigma=5.0,
        weight_background=0.1,
    )
    r = GlslRenderer()
    r.upload(scene)
    cam = front_camera(64, 48)
    for spec, opts in [
        ("wsr", {"depth_correct": True}),
        ("wsr:2", {}),
        ("duplex", {"depth_correct": True}),
        ("duplex:3", {"et_grade": 1.5, "cell_size": 3}),
        ("duplex", {"cell_size": 9}),
    ]:
        m = compare(scene, cam, spec, renderer=r, background=(0.3, 0.2, 0.1), **opts)
        assert m["max"] < 1e-3, (spec, opts, m)
    r.release()


def test_wsr_huge_view_weights(gl):
    """View weights of 10^6..10^9: both backends cap alpha and each weighted colour at WSR_FIXED_MAX (the CPU's
    int64 fixed-point bound), so they weigh the splats alike (uncapped float sums would not match the CPU)."""
    base = awkward_scene(10, n=1500)
    vw = np.zeros((base.num_splats, 4))
    vw[:, 0] = np.random.default_rng(10).uniform(1e6, 1e9, base.num_splats)
    scene = gb.Scene.from_arrays(
        base.means, base.scales, base.quats, base.opacities, base.sh, view_weight_sh=vw, weight_background=0.5
    )
    for spec in ("wsr", "wsr:2"):
        m = compare(scene, front_camera(64, 48), spec, background=(0.3, 0.2, 0.1))
        assert m["max"] < 1e-3, (spec, m)


def test_debug_planes(gl, bundled_scene):
    cam = gb.orbit_camera(bundled_scene, width=64, height=48)
    s = RenderSettings.parse("gaussian_blending:2", debug="window")
    ref = gb.get_renderer(bundled_scene, "cpu").render(cam, s)
    out = gb.get_renderer(bundled_scene, "glsl").render(cam, s)
    assert out.debug["window"].shape == (48, 64, 2) and out.debug["evals"].dtype == np.int32
    assert np.abs(out.debug["window"] - ref.debug["window"]).mean() < 1e-3
    assert abs(out.stats.evaluations - ref.stats.evaluations) <= 1e-3 * ref.stats.evaluations
    assert out.stats.evals_per_pixel == pytest.approx(out.stats.evaluations / (cam.width * cam.height))
    assert out.stats.total_ms > 0 and min(out.stats.preprocess_ms, out.stats.sort_ms, out.stats.blend_ms) >= 0
    assert out.stats.backend == "glsl" and out.stats.mode == s.label
