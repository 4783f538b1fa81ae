"""The render thread: latest request per slot, stale requests dropped, errors reported, a backend that stops
working replaced by the next pick; the slot policies of the render and trace threads."""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
import weakref

import numpy as np
import pytest
from test_state import loaded

import gbviewer as gb
from gbviewer.app.inspector.state import TraceRequest, TraceThread
from gbviewer.app.panes import PaneRenders
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads.worker import RENDER_NICE, RenderJob, RenderPolicy, RenderWorker
from gbviewer.render import BACKENDS, CpuRenderer, RenderSettings
from gbviewer.render.glsl.context import standalone_context


def test_worker_renders_latest_request_per_slot_and_drops_stale_ones(bundled_scene):
    w = RenderWorker()
    try:
        cam = gb.orbit_camera(bundled_scene, width=64, height=48)
        for k in range(5):  # five requests for one slot in a burst: at most the first and the last are rendered
            w.submit(
                RenderJob(
                    ("p", "a"), bundled_scene, cam.at_sampling_rate(1 + k / 10), RenderSettings(), "cpu", {"k": k}
                )
            )
        w.submit(RenderJob(("q", "a"), bundled_scene, cam, RenderSettings("gaussian_blending"), "cpu", {"k": 9}))
        results, t0 = [], time.time()
        while (w.busy() or not results) and time.time() - t0 < 60:
            results += w.results()
            time.sleep(0.01)
        results += w.results()
        ks = [r.job.info["k"] for r in results if r.job.slot == ("p", "a")]
        assert ks[-1] == 4 and len(ks) <= 2 and w.dropped >= 3
        assert [r.job.info["k"] for r in results if r.job.slot == ("q", "a")] == [9]
        last = [r for r in results if r.job.slot == ("p", "a")][-1]
        ref = gb.render(bundled_scene, last.job.camera)
        assert np.array_equal(last.frame.rgb, ref.rgb)
        assert w.backends_ready.wait(30) and w.backends["cpu"] == (True, "")
    finally:
        w.stop()


def test_worker_reports_errors_without_dying(bundled_scene):
    w = RenderWorker()
    try:
        cam = gb.orbit_camera(bundled_scene, width=32, height=24)
        w.submit(RenderJob(1, bundled_scene, cam, RenderSettings(), "no-such-backend"))
        w.submit(RenderJob(2, bundled_scene, cam, RenderSettings(), "cpu"))
        out, t0 = [], time.time()
        while len(out) < 2 and time.time() - t0 < 30:
            out += w.results()
            time.sleep(0.01)
        by = {r.job.slot: r for r in out}
        assert by[1].frame is None and "no-such-backend" in by[1].error
        assert by[2].frame is not None
    finally:
        w.stop()


def _render(w: RenderWorker, scene: gb.Scene, backend: str) -> list:
    w.submit(RenderJob(1, scene, gb.orbit_camera(scene, width=32, height=24), RenderSettings(), backend))
    out, t0 = [], time.time()
    while not out and time.time() - t0 < 60:
        out += w.results()
        time.sleep(0.01)
    assert out and out[0].frame is not None, out
    return out


def test_worker_frees_the_glsl_renderer_of_a_previous_scene(bundled_scene):
    """After a switch to cpu and another scene, the glsl renderer no longer keeps the first scene (and its GPU
    buffers) alive."""
    w = RenderWorker()
    try:
        assert w.backends_ready.wait(60)
        if not w.backends["glsl"][0]:
            pytest.skip(f"glsl backend unavailable: {w.backends['glsl'][1]}")
        first = gb.load(gb.DEFAULT_SCENE)
        _render(w, first, "glsl")
        gone = weakref.ref(first)
        del first
        _render(w, bundled_scene, "cpu")
        gc.collect()
        assert gone() is None
    finally:
        w.stop()


def test_a_newer_request_cancels_the_running_render_of_its_slot(bundled_scene):
    """A deliberately heavy render is running; a newer request for its slot stops it between tiles (a cancelled
    result, no frame) and is rendered next; ordering and flags only, no times."""
    w = RenderWorker()
    try:
        heavy = gb.orbit_camera(bundled_scene, width=1600, height=1200)
        first = RenderJob(("p", "a"), bundled_scene, heavy, RenderSettings("gaussian_blending", supersample=4), "cpu")
        w.submit(first)
        t0 = time.time()
        while first not in w._running and time.time() - t0 < 60:  # until the render thread has started it
            time.sleep(0.001)
        second = RenderJob(("p", "a"), bundled_scene, heavy.with_size(64, 48), RenderSettings(), "cpu")
        w.submit(second)
        results, t0 = [], time.time()
        while len(results) < 2 and time.time() - t0 < 120:
            results += w.results()
            time.sleep(0.01)
        assert [r.job for r in results] == [first, second]
        assert results[0].cancelled and results[0].frame is None and not results[0].error
        assert not results[1].cancelled and results[1].frame is not None
        assert w.cancelled == 1 and w.rendered == 1
    finally:
        w.stop()


def _collect(w: RenderWorker, until, timeout: float = 120.0) -> list:
    out, t0 = [], time.time()
    while not until(out) and time.time() - t0 < timeout:
        out += w.results()
        time.sleep(0.005)
    return out


def test_a_progressive_job_posts_its_quick_stage_then_tiles_equal_to_the_final_frame(bundled_scene):
    """Quick stage first (x1 sample, its own size), then snapshots of the refining frame whose finished tiles (the
    pixels that left the underlay, but for the tiles being written at that moment) equal the final frame's, then the
    final frame."""
    w = RenderWorker()
    snapshots: list[tuple[float, np.ndarray]] = []
    post = w._post

    def snapshot(result):  # what the UI would upload at that moment
        if result.stage == "partial":
            snapshots.append((result.progress, result.partial.copy()))
        post(result)

    w._post = snapshot
    try:
        cam = gb.orbit_camera(bundled_scene, width=640, height=480)
        settings = RenderSettings("gaussian_blending", supersample=2)
        quick = (cam.with_size(320, 240), RenderSettings("gaussian_blending"))
        underlay = np.full((10, 10, 3), np.nan, np.float32)
        job = RenderJob(1, bundled_scene, cam, settings, "cpu", progressive=True, underlay=underlay, quick=quick)
        w.submit(job)
        out = _collect(w, lambda o: any(r.stage == "final" for r in o))
        stages = [r.stage for r in out]
        assert stages[0] == "quick" and stages[-1] == "final" and set(stages) <= {"quick", "partial", "final"}
        assert out[0].frame.rgb.shape == (240, 320, 3)
        final = out[-1].frame
        ref = gb.render(bundled_scene, cam, "gaussian_blending", supersample=2)
        np.testing.assert_array_equal(final.rgb, ref.rgb)
        assert snapshots and all(0 < p < 1 for p, _ in snapshots)
        quick_up = out[0].frame.rgb.repeat(2, 0).repeat(2, 1)  # the quick stage, scaled: what is not refined yet
        for _progress, snap in snapshots:  # copied while the render went on: tiles in flight may be half done
            done = (snap != quick_up).any(axis=2)
            wrong = (done & (snap != final.rgb).any(axis=2)).reshape(60, 8, 80, 8).any(axis=(1, 3))
            assert wrong.sum() <= (os.cpu_count() or 1)  # 8x8 output pixels = one 16x16 tile of samples
            assert not np.isnan(snap).any()  # the quick stage replaced the underlay
    finally:
        w.stop()


def test_waiting_requests_of_higher_priority_go_first(bundled_scene):
    """While one render runs, a priority-1 request submitted after a priority-0 one is rendered before it."""
    w = RenderWorker()
    try:
        heavy = gb.orbit_camera(bundled_scene, width=800, height=600)
        first = RenderJob("busy", bundled_scene, heavy, RenderSettings("gaussian_blending", supersample=2), "cpu")
        w.submit(first)
        t0 = time.time()
        while first not in w._running and time.time() - t0 < 60:
            time.sleep(0.001)
        small = heavy.with_size(32, 24)
        low = RenderJob("low", bundled_scene, small, RenderSettings(), "cpu")
        high = RenderJob("high", bundled_scene, small, RenderSettings(), "cpu", priority=1)
        w.submit(low)
        w.submit(high)
        out = _collect(w, lambda o: len(o) >= 3)
        assert [r.job.slot for r in out] == ["busy", "high", "low"]
    finally:
        w.stop()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread niceness is Linux's")
def test_the_render_thread_runs_below_the_ui_priority(bundled_scene):
    w = RenderWorker()
    try:
        assert w.backends_ready.wait(60)
        ui = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        assert os.getpriority(os.PRIO_PROCESS, w._thread.native_id) == min(19, ui + RENDER_NICE)
    finally:
        w.stop()


class Flaky(CpuRenderer):
    """A fake backend: the CPU's frames until its second render, which loses the device (BackendFailed)."""

    name = "flaky"
    renders = 0  # over every instance

    def render(self, camera, settings, **kwargs):
        type(self).renders += 1
        if type(self).renders == 2:
            raise self.failed("device lost")
        return super().render(camera, settings, **kwargs)


def test_a_backend_that_stops_working_is_reported_and_its_pane_renders_on_the_next_pick(bundled_scene):
    """The second render of the flaky backend fails: the viewer says so in one line, the backend is unusable with
    its reason, auto picks past it, the pane renders on that pick and the render thread lives on."""
    Flaky.renders = 0
    w = RenderWorker(backends={"flaky": Flaky, "cpu": CpuRenderer})
    state = AppState(AppSettings())
    state.set_pane_count(1)
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    loaded(state)
    ctx = standalone_context()  # the panes' textures (the process's headless context: a window may follow)
    panes = PaneRenders(state, w, ctx)
    pane = state.panes[0]

    def render_once() -> None:
        pane.submitted.clear()  # the view is unchanged: ask again
        panes.submit()
        t0 = time.time()
        while w.busy() and time.time() - t0 < 60:
            time.sleep(0.01)
        panes.poll()

    try:
        assert w.backends_ready.wait(30) and w.backend_status("flaky") == (True, "")
        state.settings.backend = "flaky"
        render_once()
        assert pane.parts["a"].job.backend == "flaky" and pane.parts["a"].frame is not None
        render_once()  # the device is lost
        assert w.failed == {"flaky": "device lost"} and w.backends["flaky"] == (False, "stopped working: device lost")
        assert w.backend_for("flaky") == w.backend_for("auto") == "cpu" and w.auto.name == "cpu"
        assert [m[1] for m in state.messages if m[2] == "error"] == [
            "flaky stopped working: device lost; rendering on cpu"
        ]
        render_once()  # on the next pick, by the same render thread
        shown = pane.parts["a"]
        assert shown.job.backend == "cpu" and shown.error is None and w._thread.is_alive()
        np.testing.assert_array_equal(
            shown.frame.rgb,
            gb.render(state.scene, shown.job.camera, shown.job.settings.mode, shown.job.settings.supersample).rgb,
        )
        w.submit(RenderJob(9, state.scene, shown.job.camera, RenderSettings(), "flaky"))  # asked for by name
        out = _collect(w, lambda o: bool(o))
        assert out[0].failed and out[0].frame is None and Flaky.renders == 2  # no new renderer was made
    finally:
        panes.release()
        w.stop()


def test_previews_of_a_slot_do_not_cancel_each_other_but_a_full_request_cancels_a_preview():
    """The render policy: a newer preview of the running preview's slot waits; a full-resolution request (or a
    request of another slot) does not cancel wrongly. Ordering by priority, then least recently served."""
    policy = RenderPolicy()
    preview = RenderJob(1, None, None, None, preview=True)
    assert not policy.cancels(preview, RenderJob(1, None, None, None, preview=True))
    assert policy.cancels(preview, RenderJob(1, None, None, None))
    assert policy.cancels(RenderJob(1, None, None, None), RenderJob(1, None, None, None, preview=True))
    hover = RenderJob(2, None, None, None, priority=1)
    assert policy.rank(hover, 9, 5.0) < policy.rank(preview, 1, 0.0)  # priority first
    assert policy.rank(preview, 9, 1.0) < policy.rank(preview, 1, 2.0)  # then the least recently served slot


def test_the_trace_thread_lets_a_running_request_finish_and_traces_on_a_tracing_backend():
    gate, started = threading.Event(), threading.Event()

    def trace(req):
        started.set()
        gate.wait(30)
        return req.x

    t = TraceThread(trace)
    try:
        assert BACKENDS[t.backend].capabilities.trace
        first = TraceRequest("s", None, None, None, None, 1, 0)
        t.submit(first)
        assert started.wait(30)
        t.submit(TraceRequest("s", None, None, None, None, 2, 0))
        assert not t._cancel.is_set()  # not cancellable: it finishes
        gate.set()
        t0 = time.time()
        while (t.busy() or t.done < 2) and time.time() - t0 < 30:
            time.sleep(0.01)
        assert [r.trace for r in t.results()] == [1, 2]
    finally:
        gate.set()
        t.stop()
