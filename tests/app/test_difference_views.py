"""The difference and error views without a window: what the analysis thread computes for a pane part's frame, what
the pane shows of it, the PSNR/SSIM labels (equal to gbviewer.outputs.metrics on the same images) and their
staleness."""

from __future__ import annotations

import time

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.difference.thread import AnalysisThread, Request, Spec
from gbviewer.app.difference.views import PaneAnalysis
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads.worker import RenderJob
from gbviewer.outputs import differences, flicker, metrics


def wait_results(thread: AnalysisThread, n: int = 1, timeout: float = 60.0) -> list:
    got, t0 = [], time.perf_counter()
    while len(got) < n:
        assert time.perf_counter() - t0 < timeout, "the analysis thread did not answer"
        got += thread.results()
        time.sleep(0.01)
    return got


@pytest.fixture
def thread():
    t = AnalysisThread()
    yield t
    t.stop()


def test_thread_computes_references_differences_and_psnr(thread, bundled_scene, output_view):
    cam = output_view.at_sampling_rate(0.5)
    gbs = gb.RenderSettings("gaussian_blending")
    frame = gb.render(bundled_scene, cam, "gaussian_blending")
    scalar = gb.RenderSettings("scalar")
    thread.submit(Request("x", bundled_scene, frame, cam, 0.5, gbs, Spec("dense", scalar)))
    ((slot, a),) = wait_results(thread)
    dense = gb.render(bundled_scene, cam, "scalar", supersample=8).rgb
    assert slot == "x" and a.frame is frame and a.note == ""
    assert a.psnr == metrics.psnr(frame.rgb, dense) and a.ssim == metrics.ssim(frame.rgb, dense)
    np.testing.assert_array_equal(a.error, differences.signed_difference(frame.rgb, dense))
    assert a.error_scale == differences.robust_scale(a.error)
    np.testing.assert_array_equal(a.diff, differences.signed_difference(frame.rgb, gb.render(bundled_scene, cam).rgb))
    # the box reference at x1/2: the x1 render box-downsampled; none at x2 (and it says why)
    thread.submit(Request("x", bundled_scene, frame, cam, 0.5, gbs, Spec("box")))
    ((_, a),) = wait_results(thread)
    box = metrics.box_downsample(gb.render(bundled_scene, cam.at_sampling_rate(2)).rgb, 2)
    assert a.psnr == pytest.approx(metrics.psnr(frame.rgb, box), abs=1e-9) and a.diff is None
    thread.submit(Request("x", bundled_scene, frame, cam, 2.0, gbs, Spec("box")))
    ((_, a),) = wait_results(thread)
    assert a.psnr is None and a.error is None and "dense" in a.note
    # pane A's own frame at the same camera is used as it is
    other = gb.Frame(np.zeros_like(frame.rgb), frame.alpha, frame.stats, {})
    thread.submit(Request("x", bundled_scene, frame, cam, 0.5, gbs, Spec(None, scalar), other))
    ((_, a),) = wait_results(thread)
    np.testing.assert_array_equal(a.diff, frame.rgb.clip(0, 1).mean(axis=2))


def test_flicker_view_is_the_heat_map_of_an_orbit_step(bundled_scene, output_view):
    cam = output_view.at_sampling_rate(0.5)
    state = panes_with_frames(bundled_scene, cam)
    an = PaneAnalysis(state)
    try:
        b = state.panes[1].parts["a"]
        state.set_pane(1, view="flicker")
        assert "computing" in an.visualize((1, "a"), b.frame, "flicker")[1]
        settle(an)
        want = flicker.measure_flicker(
            bundled_scene,
            flicker.orbit_path(cam, bundled_scene, 2, flicker.VIEW_STEP),
            [b.job.settings],
            pairs=1,
            with_floor=False,
        ).modes[0]
        a = an.latest[(1, "a")]
        np.testing.assert_array_equal(a.heat, want.heat)
        assert a.flicker == want.flicker > 0 and a.heat.shape == b.frame.rgb.shape[:2]
        rgb, legend = an.visualize((1, "a"), b.frame, "flicker")
        np.testing.assert_array_equal(rgb, flicker.heat_colours(want.heat, flicker.heat_scale([want.heat])))
        assert legend.startswith(f"B flicker {want.flicker:.3f} levels")
        assert (0, "a") not in an.latest  # pane A shows its colour: nothing asked
    finally:
        an.stop()


def test_a_newer_request_replaces_the_waiting_one_and_cancels_the_running_one(thread, bundled_scene, output_view):
    small = output_view.at_sampling_rate(0.25)
    big = output_view.with_size(640, 480)  # its dense reference takes long enough to queue behind it
    frames = [gb.render(bundled_scene, small, m) for m in ("scalar", "mip", "gaussian_blending")]
    big_frames = [gb.render(bundled_scene, big, m) for m in ("scalar", "mip")]
    s = gb.RenderSettings()
    thread.submit(Request("big", bundled_scene, big_frames[0], big, 1.0, s, Spec("dense")))
    while not thread.busy():
        time.sleep(0.001)
    for f in frames[1:]:  # waits behind "big"; the second replaces the first
        thread.submit(Request("x", bundled_scene, f, small, 0.25, s, Spec("dense")))
    thread.submit(Request("big", bundled_scene, big_frames[1], big, 1.0, s, Spec("dense")))  # cancels the first
    got = wait_results(thread, 2)
    assert thread.done == 2 and not thread.busy()
    assert {slot: a.frame for slot, a in got} == {"x": frames[2], "big": big_frames[1]}


def panes_with_frames(scene, camera, rate=0.5) -> AppState:
    """Two panes (scalar, gaussian_blending) showing full-resolution frames at `camera`, the camera at rest."""
    state = AppState(AppSettings())
    state.scene = scene
    state.set_pane_count(2)
    state.set_pane(0, mode="scalar", supersample=1)
    state.set_pane(1, mode="gaussian_blending", supersample=1)
    state.settings.rate = rate
    state.last_move = 0.0
    for i in range(2):
        settings = state.settings_for(i, "a")
        shown = state.panes[i].parts["a"]
        shown.frame = gb.get_renderer(scene).render(camera, settings)
        shown.job = RenderJob((i, "a"), scene, camera, settings, info={"preview": 1.0, "rate": rate})
        shown.stage = "final"
    return state


def settle(an: PaneAnalysis, timeout: float = 60.0) -> None:
    t0 = time.perf_counter()
    an.update()
    while not an.current():
        assert time.perf_counter() - t0 < timeout, "no analysis"
        time.sleep(0.01)
        an.update()


def test_difference_view_and_psnr_labels(bundled_scene, output_view):
    cam = output_view.at_sampling_rate(0.5)
    state = panes_with_frames(bundled_scene, cam)
    an = PaneAnalysis(state)
    try:
        a_rgb, b_rgb = (state.panes[i].parts["a"].frame.rgb for i in range(2))
        b = state.panes[1].parts["a"]
        state.hover = (1, 0.5, 0.5)
        an.toggle_difference()  # the X key over pane B
        assert state.settings.panes[1].view == "difference"
        rgb, legend = an.visualize((1, "a"), b.frame, "difference")  # before the thread answered: the render
        assert rgb is b.frame.rgb and "computing" in legend
        settle(an)
        d = differences.signed_difference(b_rgb, a_rgb)
        rgb, legend = an.visualize((1, "a"), b.frame, "difference")
        scale = differences.robust_scale(d)
        np.testing.assert_array_equal(rgb, differences.colour_difference(d, scale))
        assert an.shown_scale[(1, "a")] == scale and legend == "B - A (scalar): mode gaussian_blending vs scalar"
        assert b.view == ""  # the result asked the panes to re-colour it
        an.set_scale(False, 0.02)
        np.testing.assert_array_equal(
            an.visualize((1, "a"), b.frame, "difference")[0], differences.colour_difference(d, 0.02)
        )
        assert an.fidelity_line((1, "a")) is None  # labels off, no error view
        # PSNR / SSIM labels against the box reference: x1 scalar box-downsampled
        an.toggle_fidelity()
        settle(an)
        box = metrics.box_downsample(gb.render(bundled_scene, cam.at_sampling_rate(2)).rgb, 2)
        for i, rgb in enumerate((a_rgb, b_rgb)):
            text, stale = an.fidelity_line((i, "a"))
            p, s = metrics.psnr(rgb, box), metrics.ssim(rgb, box)
            assert an.latest[(i, "a")].psnr == pytest.approx(p, abs=1e-9)
            assert text.startswith(f"PSNR {p:.2f} dB  SSIM {s:.4f} vs box") and not stale
        # the error view of pane A against the dense reference (Shift+P cycles the reference)
        state.hover = (0, 0.5, 0.5)
        an.toggle_error()
        an.next_reference()
        assert an.options.reference == "dense" and an.fidelity_line((0, "a"))[1]  # stale: another reference
        settle(an)
        dense = gb.render(bundled_scene, cam, "scalar", supersample=8).rgb
        e = differences.signed_difference(a_rgb, dense)
        rgb, legend = an.visualize((0, "a"), state.panes[0].parts["a"].frame, "error")
        np.testing.assert_array_equal(rgb, differences.colour_difference(e, 0.02))
        assert legend == "A - dense reference"
        assert an.fidelity_line((0, "a"))[0].startswith(f"PSNR {metrics.psnr(a_rgb, dense):.2f} dB")
        # a new frame on pane B: its label is stale until analysed, and nothing is asked while the camera moves
        b.frame = gb.render(bundled_scene, cam, "mip")
        state.moved()
        computed = an.thread.done
        an.update()
        assert an.fidelity_line((1, "a"))[1] and "(stale)" in an.fidelity_line((1, "a"))[0]
        assert "camera stops" in an.visualize((1, "a"), b.frame, "difference")[1]
        assert not an.thread.busy() and an.thread.done == computed
        state.last_move = 0.0
        settle(an)
        assert not an.fidelity_line((1, "a"))[1]
        # another scene: the results go, the thread lets go of the previous scene and its references
        state.scene = gb.load(gb.DEFAULT_SCENE)
        an.update()
        assert an.latest == {} and an.fidelity_line((0, "a")) == ("dense: computing...", True)
        t0 = time.perf_counter()
        while an.thread._scene is not None or an.thread.busy():
            assert time.perf_counter() - t0 < 10
            time.sleep(0.01)
        assert an.thread._cache == {}
    finally:
        an.stop()
