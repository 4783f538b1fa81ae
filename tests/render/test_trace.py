"""gb.trace_pixel: the native CPU kernel's own record of one pixel (native/cpu/trace.cpp), held to the rendered
frame (colour and transmittance to 1e-5 in every mode and supersampling), to its own arithmetic (weights times
colours plus T times the background give each sample's colour), to the float64 reference's choice of which splats a
sample adds, and to the paper's Figure 3 case."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import random_view
from reference import pixel_contributors

import gbviewer as gb
from gbviewer import _native
from gbviewer.core.errors import RenderError
from gbviewer.model.cells import cells_for
from gbviewer.render import Mode, RenderSettings
from gbviewer.render.modes import PER_PIXEL_SORTED
from gbviewer.render.prepare import oit_params
from gbviewer.render.trace import SKIP_REASONS

MODES = [m.label for m in Mode]
TOL = 1e-5
BACKGROUND = (0.2, 0.5, 0.8)
SORTED = ("scalar", "mip", "analytic", "gaussian_blending", "stochastic", "stochastic_popfree")


def check_trace(trace: gb.PixelTrace, frame: gb.Frame, x: int, y: int) -> None:
    """The trace is the rendered pixel, and its records add up to it."""
    np.testing.assert_allclose(trace.color, frame.rgb[y, x], atol=TOL, rtol=0)
    assert abs(trace.transmittance - (1.0 - frame.alpha[y, x])) <= TOL
    n = trace.supersample
    assert len(trace.samples) == n * n
    np.testing.assert_allclose(np.mean([s.color for s in trace.samples], 0), trace.color, atol=TOL, rtol=0)
    bg = np.asarray(trace.background)
    for k, sample in enumerate(trace.samples):
        assert x <= sample.position[0] < x + 1 and y <= sample.position[1] < y + 1
        steps = sample.steps
        added = [s for s in steps if not s.rejected]
        if trace.mode.startswith("stochastic_popfree"):  # each added fragment replaces the one before: the last shows
            added = added[-1:]
        total = sum((s.weight * np.asarray(s.color) for s in added), np.zeros(3))
        np.testing.assert_allclose(total + sample.transmittance * bg, sample.color, atol=TOL, rtol=0)
        assert all(s.sample == k and s.rejected in SKIP_REASONS for s in steps)
        for a, b in zip(steps, steps[1:]):
            assert a.T_after == b.T_before
        for s in steps:
            if s.rejected:
                assert s.weight == 0 and s.T_after == s.T_before
        stops = [i for i, s in enumerate(steps) if s.stopped]
        assert len(stops) <= 1
        after = steps[stops[0] + 1 :] if stops else []
        assert all(s.rejected == "terminated" for s in after)
        assert sum(s.rejected == "terminated" for s in steps) == len(after)
        if trace.mode.split()[0] in SORTED:
            assert all(a.depth <= b.depth for a, b in zip(steps, steps[1:]))
        if trace.mode.startswith("wsr"):
            assert not stops and all(s.T_before == 1.0 for s in steps)
            assert [s.index for s in steps] == sorted(s.index for s in steps)
        if steps and stops == [] and not trace.mode.startswith(("wsr", "duplex")):
            assert abs(steps[-1].T_after - sample.transmittance) <= TOL


@pytest.fixture(scope="module")
def zoomed_out(bundled_scene) -> gb.Camera:
    """The bundled scene at x1/8 of a 640x480 orbit view: 80x60 pixels."""
    return gb.orbit_camera(bundled_scene, 30, 20, width=640, height=480).at_sampling_rate(1 / 8)


@pytest.mark.parametrize("supersample", [1, 2, 3])
@pytest.mark.parametrize("mode", MODES)
def test_trace_is_the_rendered_pixel_bundled_scene(bundled_scene, zoomed_out, mode, supersample):
    frame = gb.render(bundled_scene, zoomed_out, mode, supersample, background=BACKGROUND)
    for x, y in [(40, 30), (16, 15), (63, 41)]:
        trace = gb.trace_pixel(bundled_scene, zoomed_out, x, y, mode, supersample, background=BACKGROUND)
        check_trace(trace, frame, x, y)
        assert sum(not s.rejected for s in trace.steps) > 0


@pytest.mark.parametrize("supersample", [1, 2, 3])
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed", [21])
def test_trace_is_the_rendered_pixel_random_scenes(seed, mode, supersample):
    scene, cam = random_view(seed, n=120)
    frame = gb.render(scene, cam, mode, supersample, background=BACKGROUND)
    rng = np.random.default_rng(seed)
    for x, y in zip(rng.integers(0, cam.width, 6), rng.integers(0, cam.height, 6)):
        check_trace(gb.trace_pixel(scene, cam, x, y, mode, supersample, background=BACKGROUND), frame, x, y)


@pytest.mark.parametrize("spec", ["preset:gsplat-antialiased", "preset:supersplat:2", "preset:antimatter15"])
def test_trace_of_a_preset_is_its_rendered_pixel(spec):
    """Presets trace with their own filter: the trace is the preset's rendered pixel, and not the scalar mode's."""
    scene, cam = random_view(22, n=120)
    frame = gb.render(scene, cam, spec, background=BACKGROUND)
    plain = gb.render(scene, cam, "scalar", RenderSettings.parse(spec).supersample, background=BACKGROUND)
    assert not np.array_equal(frame.rgb, plain.rgb)
    rng = np.random.default_rng(22)
    for x, y in zip(rng.integers(0, cam.width, 6), rng.integers(0, cam.height, 6)):
        trace = gb.trace_pixel(scene, cam, x, y, spec, background=BACKGROUND)
        check_trace(trace, frame, x, y)
        assert trace.mode.startswith("preset:")


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize(
    "mode",
    [
        m
        for m in MODES
        if not m.startswith("stochastic")  # test_stochastic.py
        and Mode[m.upper()] not in PER_PIXEL_SORTED
    ],
)  # test_stopthepop.py
@pytest.mark.parametrize("seed", [11, 13])
def test_added_splats_are_the_references(seed, mode, supersample):
    """Per sample, the splats the trace adds (rejected == "") are those the float64 reference renderer adds, in
    the same order (wsr, duplex: as sets: the order inside their lists is free); samples where the reference saw a
    threshold tie are left out."""
    scene, cam = random_view(seed, n=120, filter3d=seed == 13)
    settings = RenderSettings(mode, supersample, cell_size=4)
    oit = oit_params(scene, settings)._asdict() if mode in ("wsr", "duplex") else None
    cells = cells_for(scene, 4) if mode == "duplex" else None
    rng = np.random.default_rng(seed)
    compared = added = rejected = 0
    for x, y in zip(rng.integers(0, cam.width, 6), rng.integers(0, cam.height, 6)):
        trace = gb.trace_pixel(scene, cam, x, y, mode, supersample, cell_size=4)
        reference = pixel_contributors(scene, cam, mode, x, y, supersample, oit, cells)
        for sample, (ref_added, tie) in zip(trace.samples, reference):
            if tie:
                continue
            got = [s.index for s in sample.steps if not s.rejected]
            if mode in ("wsr", "duplex"):
                got, ref_added = sorted(got), sorted(ref_added)
            assert got == ref_added, (x, y, sample.position)
            compared += 1
            added += len(got)
            rejected += sum(1 for s in sample.steps if s.rejected)
    assert compared >= 5 * supersample**2 and added > 0 and rejected > 0


def figure3_scene(mu_x: float = 0.5, sigma: float = 1.0, f: float = 100.0) -> tuple[gb.Scene, gb.Camera]:
    """The paper's Figure 3 pair: splats of opacity 1 and sigma `sigma` px at (mu_x, -0.1) (front, red) and
    (mu_x, +0.1) (behind, blue) from the centre of pixel (8, 8) of a 16x16 image."""
    cam = gb.Camera(16, 16, f, f, 8.0, 8.0, np.eye(3), np.zeros(3))
    z = np.array([2.0, 3.0])
    means = np.stack([(0.5 + mu_x) * z / f, (0.5 + np.array([-0.1, 0.1])) * z / f, z], 1)
    scales = np.stack([sigma * z / f, sigma * z / f, np.full(2, 1e-5)], 1)
    sh = np.zeros((2, 1, 3))
    sh[0, 0], sh[1, 0] = [1.0, -0.5, -0.5], [-0.5, -0.5, 1.0]
    return gb.Scene.from_arrays(means, scales, np.tile([1.0, 0, 0, 0], (2, 1)), np.ones(2), sh), cam


def figure3_exact(mu_x: float = 0.5, sigma: float = 1.0, n: int = 400) -> tuple[float, float]:
    """Eq. 6 over the pixel by the midpoint rule (float64): the back splat's weight and the final transmittance."""
    g = (np.arange(n) + 0.5) / n - 0.5
    X, Y = np.meshgrid(g, g)
    a1, a2 = (np.minimum(0.99, np.exp(-0.5 * ((X - mu_x) ** 2 + (Y - dy) ** 2) / sigma**2)) for dy in (-0.1, 0.1))
    return float((a2 * (1 - a1)).mean()), float(((1 - a1) * (1 - a2)).mean())


def test_figure3_background_splat_gets_more_weight_under_gaussian_blending():
    """Figure 3 (mu_x = 0.5, sigma = 1): scalar blending lets the front splat's centre value occlude the whole pixel,
    so the splat behind gets too little weight; the Gaussian Blending window moves off the front splat and gives it
    about the exact (eq. 6) weight, and the transmittance error is the smallest of the single-sample modes."""
    scene, cam = figure3_scene()
    traces = {m: gb.trace_pixel(scene, cam, 8, 8, m) for m in ("scalar", "analytic", "gaussian_blending")}
    back = {m: dict(t.contributions()).get(1, 0.0) for m, t in traces.items()}
    exact_w, exact_T = figure3_exact()
    assert back["gaussian_blending"] > back["scalar"] + 0.03
    assert abs(back["gaussian_blending"] - exact_w) < 2e-3 < abs(back["scalar"] - exact_w)
    dT = {m: abs(t.transmittance - exact_T) for m, t in traces.items()}
    assert dT["gaussian_blending"] < 1e-3 and dT["gaussian_blending"] * 5 < min(dT["scalar"], dT["analytic"])
    gbt = traces["gaussian_blending"].steps
    assert [s.index for s in gbt if not s.rejected] == [0, 1]
    front = gbt[0]
    assert front.window_center[0] < 8.5 and front.window_size[0] < 1.0  # moved away from the front splat (x > 8.5)


def test_pixel_boxes_only_skip_what_the_steps_reject(bundled_scene, zoomed_out):
    """With the pixel boxes off every entry is evaluated: no "outside_box" records, the same colour."""
    with_boxes = gb.trace_pixel(bundled_scene, zoomed_out, 40, 30, "scalar")
    _native.testing.set_pixel_boxes(False)
    try:
        without = gb.trace_pixel(bundled_scene, zoomed_out, 40, 30, "scalar")
    finally:
        _native.testing.set_pixel_boxes(True)
    assert with_boxes.rejected_counts().get("outside_box", 0) > 0 and "outside_box" not in without.rejected_counts()
    assert without.color == with_boxes.color
    assert [s.index for s in without.steps if not s.rejected] == [s.index for s in with_boxes.steps if not s.rejected]


def test_geometry_and_json(bundled_scene, zoomed_out):
    """Per step: the covariance is the conic's inverse (output pixels); the window after each entry (gaussian
    blending); to_json carries every step."""
    trace = gb.trace_pixel(bundled_scene, zoomed_out, 40, 30, "gaussian_blending", 2)
    conic = np.array([[[s.conic[0], s.conic[1]], [s.conic[1], s.conic[2]]] for s in trace.steps])
    cov = np.array([[[s.covariance[0], s.covariance[1]], [s.covariance[1], s.covariance[2]]] for s in trace.steps])
    np.testing.assert_allclose(conic @ cov, np.broadcast_to(np.eye(2), conic.shape), atol=1e-3)
    assert all(s.window_size[0] > 0 and s.window_size[1] > 0 for s in trace.steps)
    first = trace.samples[0].steps[0]
    assert first.window_center == pytest.approx(trace.samples[0].position) or not first.rejected
    doc = json.loads(trace.to_json())
    assert doc["color"] == list(trace.color) and doc["mode"] == "gaussian_blending 2x2"
    assert [len(s["steps"]) for s in doc["samples"]] == [len(s.steps) for s in trace.samples]
    assert doc["samples"][0]["steps"][0]["window_size"] == list(first.window_size)


@pytest.mark.parametrize("x, y", [(80, 0), (0, 60), (-1, 5)])
def test_pixel_outside_the_image(bundled_scene, zoomed_out, x, y):
    with pytest.raises(RenderError, match=r"outside the 80x60 image"):
        gb.trace_pixel(bundled_scene, zoomed_out, x, y)
    with pytest.raises(RenderError, match="pixel x"):
        gb.trace_pixel(bundled_scene, zoomed_out, 1.5, 2)
