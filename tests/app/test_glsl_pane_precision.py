"""A glsl pane's gaussian_blending: the viewer asks for the fast kernel, the glsl backend runs it, and the pane label
and the frame's FrameStats say so."""

from __future__ import annotations

import time
from dataclasses import replace

from helpers import skip_or_fail
from test_lod_previews import FakeWorker, opened
from test_stochastic_panes import FakeApp

import gbviewer as gb
from gbviewer.app.overlays.labels import pane_label
from gbviewer.app.panes import PaneRenders
from gbviewer.app.threads.worker import RenderResult
from gbviewer.render import BACKENDS
from gbviewer.render.glsl import GlslRenderer
from gbviewer.render.glsl.context import standalone_context


class GlslWorker(FakeWorker):
    def backend_for(self, name: str) -> str:
        return "glsl"

    def capabilities(self, name: str):
        return BACKENDS["glsl"].capabilities


def test_a_glsl_pane_says_which_precision_rendered(monkeypatch):
    ok, why = GlslRenderer.available()
    if not ok:
        skip_or_fail(why)
    state = opened(monkeypatch, [False])
    worker = GlslWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        state.set_pane(1, mode="gaussian_blending")
        panes.submit()
        job = next(j for j in worker.jobs if j.slot == (1, "a"))
        assert job.backend == "glsl" and job.settings.precision == "fast"
        renderer = gb.get_renderer(state.scene, "glsl")
        frame = renderer.render(job.camera, job.settings)
        panes._take(RenderResult(job, frame, finished=time.perf_counter()))
        assert (frame.stats.backend, frame.stats.precision) == ("glsl", "fast")
        assert frame.stats.mode == "gaussian_blending fast"
        assert pane_label(FakeApp(state), state.panes[1], "a").split("  ")[1] == "gaussian_blending fast"
        exact = renderer.render(job.camera, replace(job.settings, precision="exact"))
        assert (exact.stats.precision, exact.stats.mode) == ("exact", "gaussian_blending")  # kernels: test_gb_fast_glsl
    finally:
        panes.release()


def test_a_pane_can_be_switched_to_the_exact_kernel(monkeypatch):
    """'gaussian_blending+exact' is one of the panes' modes: it renders (and says) exact, beside a fast pane, and
    survives the settings file."""
    state = opened(monkeypatch, [False])
    state.set_pane(0, mode="gaussian_blending")
    state.set_pane(1, mode="gaussian_blending+exact")
    assert state.settings_for(0, "a").precision == "fast"
    assert state.settings_for(1, "a").precision == "exact"
    assert state.settings.panes[1].normalised().mode == "gaussian_blending+exact"
    frame = gb.render(state.scene, state.pane_camera(1), state.settings_for(1, "a"))
    assert (frame.stats.precision, frame.stats.mode) == ("exact", "gaussian_blending")
