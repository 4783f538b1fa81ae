"""The render thread: latest request per slot, stale requests dropped, errors reported."""

from __future__ import annotations

import gc
import time
import weakref

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.worker import RenderJob, RenderWorker
from gbviewer.render import RenderSettings


def test_worker_renders_latest_request_per_slot_and_drops_stale_ones(bundled_scene):
    w = RenderWorker()
    try:
        cam = gb.orbit_camera(bundled_scene, width=64, height=48)
        for k in range(5):  # five requests for one slot in a burst: at most the first and the last are rendered
            w.submit(RenderJob(("p", "a"), bundled_scene, cam.at_sampling_rate(1 + k / 10), RenderSettings(), "cpu",
                               {"k": k}))
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
        while w._running is not first and time.time() - t0 < 60:  # until the render thread has started it
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
