"""stopthepop (per-pixel order by the depth of the ray maximum, through StopThePop's hierarchy ending in a K-entry
queue) against the float64 references of tests/reference_ray.py: an unbounded queue is the exact per-pixel sort;
the mode grammar; and popping on an orbit over a scene whose two splats swap their centre order while their per-pixel
order does not (gbviewer.outputs.flicker). The hierarchy against its own reference: test_stopthepop_hier.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import random_view
from reference_ray import render_sorted
from reference_stopthepop import render_hierarchical
from simd_helpers import ALL_PATHS
from simd_helpers import render as render_on

import gbviewer as gb
from gbviewer import lod
from gbviewer.core.errors import RenderError
from gbviewer.model.scene import SH_C0
from gbviewer.outputs import flicker as fl
from gbviewer.render import RenderSettings, create_renderer
from gbviewer.render.view_filter import ViewFilter

W, H = 48, 40


def camera() -> gb.Camera:
    return gb.Camera(W, H, 40.0, 40.0, 24.5, 20.5, np.eye(3), np.zeros(3))  # pixel (24, 20) looks down +z


def random_scene(seed: int = 7, n: int = 40) -> gb.Scene:
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-0.6, 0.6, n), rng.uniform(-0.5, 0.5, n), rng.uniform(2.0, 3.0, n)], 1)
    return gb.Scene.from_arrays(
        means,
        np.exp(rng.uniform(-3.0, -0.8, (n, 3))),
        rng.normal(size=(n, 4)),
        rng.uniform(0.3, 1.0, n),
        rng.normal(0, 0.8, (n, 1, 3)),
    )


def crossing_splats(y: float = 0.0) -> gb.Scene:
    """Five long splats tilted 45 degrees about y whose axes all cross the ray of pixel (24, 20) (at height y): in the
    order of their centres' depths (2.0 .. 2.4) their maxima along that ray lie at depths 3.0, 2.9, 2.8, 2.7 and 1.9,
    so a queue of four alone blends the fifth after the fourth (a fragment nearer than one already blended)."""
    zc = np.array([2.0, 2.1, 2.2, 2.3, 2.4])
    tstar = np.array([3.0, 2.9, 2.8, 2.7, 1.9])
    means = np.stack([zc - tstar, np.full(5, y), zc], 1)  # axis (1, 0, 1) / sqrt 2 meets x = 0 at z = zc - x
    quat = (math.cos(math.pi / 8), 0.0, math.sin(math.pi / 8), 0.0)  # 45 degrees about y: x axis -> (1, 0, -1)
    quats = np.tile(quat, (5, 1))
    quats[:, 2] *= -1  # x axis -> (1, 0, 1) / sqrt 2
    colours = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [0.2, 0.2, 0.2]], np.float64)
    return gb.Scene.from_arrays(
        means, np.tile([1.2, 0.03, 0.03], (5, 1)), quats, np.full(5, 0.8), ((colours - 0.5) / SH_C0)[:, None, :]
    )


def test_unbounded_queue_is_the_exact_per_pixel_sort():
    scene, cam = random_scene(), camera()
    rgb, alpha = render_sorted(scene, cam, "stopthepop", queue=0)
    frame = gb.render(scene, cam, "stopthepop:0")
    err = np.abs(frame.rgb - rgb).max(axis=2)
    assert np.quantile(err, 0.995) < 1e-4 and err.max() < 5e-3
    np.testing.assert_allclose(frame.alpha, alpha, atol=5e-3)
    # a queue longer than any pixel's fragments (40 splats) is the same sort, bit for bit
    assert np.array_equal(gb.render(scene, cam, "stopthepop:64").rgb, frame.rgb)
    assert np.abs(render_sorted(scene, cam, "stopthepop", queue=1)[0] - rgb).max() > 0.05  # the order matters here


@pytest.mark.parametrize("path", ALL_PATHS[1:])
@pytest.mark.parametrize("mode", ["eval3d", "stopthepop", "stopthepop:0"])
def test_every_simd_path_is_bit_identical(path, mode):
    """Every kind of awkward splat (behind, degenerate, huge, near the plane, off screen): the per-pixel walk is the
    scalar path's on every path, and the preprocess is bitwise the same, so every pixel is too."""
    for seed in (1, 2):
        scene, cam = random_view(seed, n=200, W=45, H=37)
        for supersample in (1, 2):
            ref = render_on("scalar", scene, cam, mode, supersample)
            vec = render_on(path, scene, cam, mode, supersample)
            assert np.isfinite(ref.rgb).all() and ref.alpha.max() > 0
            assert np.array_equal(vec.rgb, ref.rgb) and np.array_equal(vec.alpha, ref.alpha)
            assert np.array_equal(vec.debug["evals"], ref.debug["evals"])


def test_grammar():
    s = RenderSettings.parse("stopthepop:8")
    assert (s.mode, s.queue, s.supersample, s.spec, s.label) == (
        gb.Mode.STOPTHEPOP,
        8,
        1,
        "stopthepop:8",
        "stopthepop:8",
    )
    s = RenderSettings.parse("stopthepop:4:2")
    assert (s.queue, s.supersample, s.spec, s.label) == (4, 2, "stopthepop:4:2", "stopthepop 2x2")
    assert RenderSettings.parse(s.spec) == s
    assert RenderSettings.parse("stopthepop").queue == 4
    assert RenderSettings.parse("eval3d:3").supersample == 3
    for bad in ("stopthepop:x", "stopthepop:65", "stopthepop:-1"):
        with pytest.raises(RenderError):
            RenderSettings.parse(bad)
    with pytest.raises(RenderError, match="queue"):
        RenderSettings(gb.Mode.SCALAR, queue=8)


@pytest.mark.parametrize("mode", ["stopthepop", "eval3d"])
def test_no_view_filter_or_preset_rule(mode):
    """stopthepop blends with 3DGS's own +0.3 (its queue of one is scalar, above); neither it nor eval3d takes a view
    filter or a preset's rules (they are not among the modes a preset's filter applies to: FILTERED_MODES)."""
    for vf in (ViewFilter(0.1), ViewFilter(dc_clamp=True), ViewFilter(support=3.0), ViewFilter(sort_radial=True)):
        with pytest.raises(RenderError, match=f"is not for {mode}"):
            RenderSettings(gb.Mode.parse(mode), view_filter=vf)


def wall_and_ball() -> gb.Scene:
    """A red wall (a flat splat in the plane z = 4) and a green ball in front of it, to the side: as the camera
    orbits, the ball's centre goes from nearer than the wall's to farther, while along every ray that meets both the
    ball stays in front."""
    means = np.array([[0.0, 0.0, 4.0], [0.9, 0.0, 3.6]])
    colours = np.array([[1.0, 0.1, 0.1], [0.1, 1.0, 0.1]])
    return gb.Scene.from_arrays(
        means,
        np.array([[0.8, 0.8, 0.01], [0.2, 0.2, 0.2]]),
        np.tile([1.0, 0, 0, 0], (2, 1)),
        np.array([0.95, 0.95]),
        ((colours - 0.5) / SH_C0)[:, None, :],
    )


def test_stopthepop_does_not_pop_on_an_orbit():
    """Flicker against the exact per-pixel sort at 4x4 samples (the default reference, scalar 8x8, pops itself):
    scalar pops where the centre order swaps, stopthepop does not."""
    scene = wall_and_ball()
    base = gb.Camera(64, 48, 50.0, 50.0, 32, 24, np.eye(3), np.zeros(3))
    path = fl.orbit_path(base, scene, 17, -60.0)
    depths = [
        (pf.camera.R @ scene.means[1] + pf.camera.t)[2] - (pf.camera.R @ scene.means[0] + pf.camera.t)[2] for pf in path
    ]
    assert min(depths) < 0 < max(depths)  # the centre order swaps along the path
    modes = RenderSettings.parse_list("scalar,stopthepop")
    rep = fl.measure_flicker(
        scene, path, modes, reference=RenderSettings.parse("stopthepop:0:4"), pairs=16, with_floor=False
    )
    scalar, stp = rep.modes
    assert scalar.flicker > 4 * stp.flicker, (scalar.flicker, stp.flicker)


@pytest.mark.parametrize("spec, order", [("stopthepop:0", [4, 3, 2, 1, 0]), ("eval3d", [4, 3, 2, 1, 0])])
def test_trace_lists_the_pixel_blend_order(spec, order):
    """The pixel trace walks the constructed pixel in its blend order (the exact sort's; the hierarchy's:
    test_stopthepop_hier.py) and gives the rendered colour."""
    scene, cam = crossing_splats(), camera()
    renderer = create_renderer("cpu")
    renderer.upload(scene)
    settings = RenderSettings.parse(spec)
    tr = renderer.trace(cam, settings, 24, 20)
    assert [s.index for s in tr.samples[0].steps] == order
    np.testing.assert_array_equal(tr.color, renderer.render(cam, settings).rgb[20, 24])


@pytest.mark.parametrize("spec", ["eval3d:2", "stopthepop:4:2"])
def test_supersampled_matches_the_reference(spec):
    """N x N samples: the reference's render at N times the resolution, box-averaged."""
    scene, cam = random_scene(9, 30), gb.Camera(24, 20, 20.0, 20.0, 12.25, 10.25, np.eye(3), np.zeros(3))
    if spec == "eval3d:2":
        rgb, _ = render_sorted(scene, cam, "eval3d", supersample=2)
    else:
        rgb, _ = render_hierarchical(scene, cam, 4, supersample=2)
    err = np.abs(gb.render(scene, cam, spec).rgb - rgb).max(axis=2)
    assert np.quantile(err, 0.99) < 1e-4 and err.max() < 5e-3


@pytest.mark.parametrize("spec", ["eval3d", "stopthepop"])
def test_level_of_detail_drawn_in_place_is_the_cut_scene(spec):
    """The cut drawn in place (its rows of the scene and the hierarchy's interior nodes) gives the image of the cut
    gathered into a scene of its own, bit for bit."""
    rng = np.random.default_rng(4)
    n = 3000
    means = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(2, 6, n)], 1)
    scene = gb.Scene.from_arrays(
        means,
        np.exp(rng.uniform(-4.0, -1.5, (n, 3))),
        rng.normal(size=(n, 4)),
        rng.uniform(0.05, 1.0, n),
        rng.normal(0, 0.5, (n, 1, 3)),
    )
    cam = gb.Camera(64, 48, 60.0, 60.0, 32, 24, np.eye(3), np.zeros(3))
    frame = gb.render(scene, cam, f"{spec}+lod:2")
    assert frame.stats.lod_splats != n  # interior nodes drawn
    assert np.array_equal(frame.rgb, gb.render(lod.cut_scene(scene, cam, 2.0), cam, spec).rgb)
