"""stopthepop:K's hierarchical resort (gbv/resort.h: tile key, 4x4 queue with culling, 2x2 queue, per-pixel queue)
against the float64 reference of the published pipeline (tests/reference_stopthepop.py): random scenes where the
hierarchy changes pixels; a pixel where the hierarchy puts right what the per-pixel queue alone blends out of order;
a pixel where the published method itself blends out of order (a near splat the tile stage sorts late), which the
exact sort (stopthepop:0) and a long enough queue do not; the pixel trace in the hierarchy's order."""

from __future__ import annotations

import math

import numpy as np
import pytest
from reference_ray import render_sorted
from reference_stopthepop import render_hierarchical
from test_stopthepop import camera, crossing_splats, random_scene

import gbviewer as gb
from gbviewer.model.scene import SH_C0
from gbviewer.render import RenderSettings, create_renderer


def late_near_splat(walls: int = 66) -> gb.Scene:
    """Faint camera-facing walls near the ray of pixel (28, 20) at depths 2.0 .. 3.3, and a long red splat whose
    centre (depth 3.5, 11.5 px to the left, in the same tile) puts it behind every wall in the tile stage, tilted so
    that it crosses that ray at depth ~1.5, nearer than every wall: it reaches the pixel in the third load of 32,
    after 32 walls went on from the 4x4 queue."""
    z = np.linspace(2.0, 3.3, walls)
    wall_means = np.stack([(28.3 - 24.5) / 40.0 * z, np.full(walls, 0.001), z], 1)  # centres off the pixel centres
    xm, zm = (17.0 - 24.5) / 40.0 * 3.5, 3.5
    axis = np.array([(28.5 - 24.5) / 40.0 * 1.5 - xm, 1.5 - zm])
    angle = math.atan2(-axis[1], axis[0])  # about y: the x axis to (cos, 0, -sin)
    means = np.vstack([wall_means, [xm, 0.001, zm]])
    scales = np.vstack([np.tile([0.3, 0.3, 0.01], (walls, 1)), [3.0, 0.03, 0.03]])
    quats = np.vstack([np.tile([1.0, 0.0, 0.0, 0.0], (walls, 1)), [math.cos(angle / 2), 0.0, math.sin(angle / 2), 0.0]])
    colours = np.vstack([np.tile([0.9, 0.9, 0.9], (walls, 1)), [1.0, 0.0, 0.0]])
    return gb.Scene.from_arrays(
        means, scales, quats, np.append(np.full(walls, 0.05), 0.8), ((colours - 0.5) / SH_C0)[:, None, :]
    )


def assert_matches(frame: gb.Frame, ref: tuple[np.ndarray, np.ndarray]) -> None:
    err = np.abs(frame.rgb - ref[0]).max(axis=2)
    assert np.quantile(err, 0.995) < 1e-4 and err.max() < 5e-3, (np.quantile(err, 0.995), err.max())
    np.testing.assert_allclose(frame.alpha, ref[1], atol=5e-3)


def differs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a - b).max(axis=2) > 0.01


@pytest.mark.parametrize("queue", [4, 1])
def test_matches_the_reference_where_the_hierarchy_matters(queue):
    scene, cam = random_scene(5, 150), camera()
    ref = render_hierarchical(scene, cam, queue)
    assert_matches(gb.render(scene, cam, f"stopthepop:{queue}"), ref)
    alone = render_hierarchical(scene, cam, queue, hierarchy=False)[0]
    exact = render_sorted(scene, cam, "stopthepop", 0)[0]
    assert differs(ref[0], alone).sum() > 100  # the hierarchy changes this scene ...
    assert 0 < differs(ref[0], exact).sum() < differs(alone, exact).sum()  # ... towards the exact order, not to it


def test_long_queue_matches_the_reference():
    scene, cam = random_scene(), camera()
    assert_matches(gb.render(scene, cam, "stopthepop:16"), render_hierarchical(scene, cam, 16))


def test_hierarchy_puts_right_what_the_pixel_queue_alone_does_not():
    """The crossing splats (test_stopthepop.crossing_splats; a little off the rows of pixel centres, where the
    published 4x4 culling tests a centre on the sub-tile's first row from the wrong side): the 4x4 and 2x2 queues
    sort them before the pixel's queue of four sees them."""
    scene, cam = crossing_splats(0.002), camera()
    ref = render_hierarchical(scene, cam, 4)
    frame = gb.render(scene, cam, "stopthepop")
    assert_matches(frame, ref)
    exact = render_sorted(scene, cam, "stopthepop", 0)[0]
    alone = render_hierarchical(scene, cam, 4, hierarchy=False)[0]
    assert np.abs(alone[20, 24] - exact[20, 24]).max() > 0.05
    assert np.abs(frame.rgb[20, 24] - exact[20, 24]).max() < 1e-4


def test_published_method_blends_a_late_near_splat_out_of_order():
    scene, cam = late_near_splat(), camera()
    orders: dict = {}
    ref = render_hierarchical(scene, cam, 4, orders=orders)
    frame = gb.render(scene, cam, "stopthepop")
    assert_matches(frame, ref)
    assert orders[28, 20].index(66) > 20  # the red splat after 20 walls
    exact = render_sorted(scene, cam, "stopthepop", 0)[0]
    assert np.abs(frame.rgb[20, 28] - exact[20, 28]).max() > 0.05
    for spec in ("stopthepop:0", "stopthepop:64"):  # unbounded: the exact sort; a queue of 64 holds them all
        np.testing.assert_allclose(gb.render(scene, cam, spec).rgb[20, 28], exact[20, 28], atol=1e-4)


@pytest.mark.parametrize("scene_fn, pixel", [(lambda: crossing_splats(0.002), (24, 20)), (late_near_splat, (28, 20))])
def test_trace_lists_the_hierarchy_blend_order(scene_fn, pixel):
    scene, cam = scene_fn(), camera()
    orders: dict = {}
    render_hierarchical(scene, cam, 4, orders=orders)
    renderer = create_renderer("cpu")
    renderer.upload(scene)
    settings = RenderSettings.parse("stopthepop")
    tr = renderer.trace(cam, settings, *pixel)
    assert [s.index for s in tr.samples[0].steps if s.weight > 0] == orders[pixel]
    np.testing.assert_array_equal(tr.color, renderer.render(cam, settings).rgb[pixel[1], pixel[0]])
