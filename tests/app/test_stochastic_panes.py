"""A stochastic pane in the viewer: while the camera is still each finished frame is followed by the next frame
index and the pane shows the running mean (its samples per pixel on the label), up to MAX_FRAMES; moving, it renders
frame 0 alone (1 sample per pixel), and a new view starts the mean again."""

from __future__ import annotations

import time

import numpy as np
from test_lod_previews import FakeWorker, opened

import gbviewer as gb
from gbviewer.app.frames import accumulate
from gbviewer.app.overlays.labels import pane_label
from gbviewer.app.panes import PaneRenders
from gbviewer.app.threads.worker import RenderResult
from gbviewer.render.glsl.context import standalone_context


class FakeApp:
    def __init__(self, state) -> None:
        self.state = state


def _finish(panes: PaneRenders, state, job) -> gb.Frame:
    frame = gb.get_renderer(state.scene, "cpu").render(job.camera, job.settings)
    panes._take(RenderResult(job, frame, finished=time.perf_counter()))
    return frame


def test_a_still_stochastic_pane_shows_the_running_mean(monkeypatch):
    moving = [False]
    state = opened(monkeypatch, moving)
    state.set_pane(0, mode="stochastic_popfree")
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        frames = []
        for k in range(3):
            worker.jobs.clear()
            panes.submit()
            job = next(j for j in worker.jobs if j.slot == (0, "a"))
            assert job.settings.frame == k and job.display == "copy" and job.progressive == (k == 0)
            frames.append(_finish(panes, state, job).rgb)
        shown = state.panes[0].parts["a"]
        np.testing.assert_allclose(shown.frame.rgb, np.mean(frames, 0), atol=1e-6)
        assert not np.array_equal(frames[0], frames[1])  # other frame indices, other samples
        assert pane_label(FakeApp(state), state.panes[0], "a").split("  ")[1].endswith(" 3 spp")
        worker.jobs.clear()
        panes.submit()  # frame 3 is in flight: nothing new until it arrives
        pending = [j for j in worker.jobs if j.slot == (0, "a")]
        worker.jobs.clear()
        panes.submit()
        assert len(pending) == 1 and not [j for j in worker.jobs if j.slot == (0, "a")]

        moving[0] = True  # moving: frame 0 alone at the preview's size, one sample per pixel
        state.controller.orbit(5.0, 0.0)
        worker.jobs.clear()
        panes.submit()
        job = next(j for j in worker.jobs if j.slot == (0, "a"))
        assert job.settings.frame == 0
        first = _finish(panes, state, job)
        np.testing.assert_array_equal(shown.frame.rgb, first.rgb)
        assert pane_label(FakeApp(state), state.panes[0], "a").split("  ")[1].endswith(" 1 spp")
    finally:
        panes.release()


def test_the_mean_stops_at_max_frames(monkeypatch):
    acc = accumulate.Accumulation()
    settings = gb.RenderSettings(gb.Mode.STOCHASTIC, 2)
    frame = gb.Frame(np.ones((2, 2, 3), np.float32), np.ones((2, 2), np.float32))
    for k in range(accumulate.MAX_FRAMES):
        assert acc.request("key", settings, moving=False).frame == k
        acc.add("key", frame, k)
    assert acc.request("key", settings, moving=False) is None and acc.samples(2) == 4 * accumulate.MAX_FRAMES
    assert acc.request("other", settings, moving=False).frame == 0  # another view starts again
    acc.add("key", frame, 7)  # not the next index (a stale frame): the sum starts again
    assert acc.frames == 1
