"""The viewer's level of detail: while the camera moves a pane's previews draw the hierarchy's cut (coarser when a
preview runs over its 100 ms, finer when well under), a still pane renders every splat unless the user chose LOD
for it in the panel (then its cut, moving or not); the pane setting persists normalised."""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

from test_state import loaded

import gbviewer as gb
from gbviewer.app import state as state_module
from gbviewer.app.frames import rates
from gbviewer.app.panes import PaneRenders
from gbviewer.app.settings import AppSettings, PaneSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads import loading
from gbviewer.app.threads.worker import RenderResult
from gbviewer.model.scene import OitData
from gbviewer.render import BACKENDS
from gbviewer.render.glsl.context import standalone_context


class FakeWorker:
    """Takes the panes' requests; renders nothing (the test hands results back itself)."""

    def __init__(self) -> None:
        self.jobs: list = []

    def backend_for(self, name: str) -> str:
        return "cpu"

    def display_path(self, name: str) -> tuple[str, str]:
        return "copy", ""

    def capabilities(self, name: str):
        return BACKENDS["cpu"].capabilities

    def submit_all(self, jobs: list) -> None:
        for job in jobs:
            job.submitted = time.perf_counter()
        self.jobs += jobs

    def results(self) -> list:
        return []

    def return_textures(self) -> None:
        pass


def opened(monkeypatch, moving: list[bool]) -> AppState:
    monkeypatch.setattr(AppState, "moving", property(lambda self: moving[0]))
    state = AppState(AppSettings())
    state.set_pane_count(2)
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    loaded(state)
    for p in state.panes:  # measured: a full render is slow, so moving drops to a preview resolution
        p.ms_per_px = {(part, ps.mode, ps.supersample, "cpu"): 1.0 for part in "ab" for ps in state.settings.panes}
    return state


def test_previews_draw_the_cut_and_still_frames_every_splat(monkeypatch):
    moving = [True]
    state = opened(monkeypatch, moving)
    state.set_pane(1, lod=4.0)  # pane B: the user's LOD
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        a, b = worker.jobs
        assert a.preview and a.settings.lod == rates.PREVIEW_LOD_PX and b.preview and b.settings.lod == 4.0
        frame = gb.get_renderer(state.scene, "cpu").render(a.camera, a.settings)  # the preview renders the cut
        assert frame.stats.lod_splats is not None and "LOD" in frame.stats.mode
        frame.stats.total_ms = 3 * rates.PREVIEW_MS  # over budget: the next preview's cut is coarser
        panes._take(RenderResult(a, frame, finished=time.perf_counter()))
        assert state.panes[0].preview_lod == 2 * rates.PREVIEW_LOD_PX
        state.controller.orbit(5.0, 0.0)  # the camera moved on
        worker.jobs.clear()
        panes.submit()
        assert [j.settings.lod for j in worker.jobs] == [2 * rates.PREVIEW_LOD_PX, 4.0]
        moving[0] = False  # stopped: pane A finishes on the full scene, pane B on its cut
        worker.jobs.clear()
        panes.submit()
        a, b = worker.jobs
        assert not a.preview and a.settings.lod is None and not b.preview and b.settings.lod == 4.0
        assert (a.camera.width, a.camera.height) == state.panes[0].render_size
    finally:
        panes.release()


def test_a_preview_cancelled_after_its_budget_coarsens_the_next_cut(monkeypatch):
    """A cut too fine for the scene never finishes while the camera moves (the stop cancels it): the time it ran
    still coarsens the next motion's previews; one cancelled within budget leaves the cut."""
    moving = [True]
    state = opened(monkeypatch, moving)
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        a = worker.jobs[0]
        t = a.submitted + 5.0  # it waited 5 s in the queue: that does not count
        panes._take(RenderResult(a, None, finished=t + 0.01, cancelled=True, started=t))  # 10 ms: within budget
        assert state.panes[0].preview_lod == rates.PREVIEW_LOD_PX
        panes._take(RenderResult(a, None, finished=t + 3.0, cancelled=True, started=t))  # ran 3 s, then stopped
        assert state.panes[0].preview_lod == 2 * rates.PREVIEW_LOD_PX
        assert state.panes[0].parts["a"].job is None  # nothing shown from it
    finally:
        panes.release()


def test_scenes_without_a_hierarchy_preview_by_resolution_alone(monkeypatch):
    moving = [True]
    state = opened(monkeypatch, moving)
    monkeypatch.setattr(type(state.scene), "oit", property(lambda self: object()))  # order-independent data
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        assert all(j.preview and j.settings.lod is None for j in worker.jobs)
    finally:
        panes.release()


def test_a_large_scene_starts_its_previews_coarse(monkeypatch):
    """A new scene's panes start at the cut its size calls for (a 6 M-splat scene at 8 px, not 1), whatever the
    previous scene's previews had come to."""
    assert [rates.first_preview_lod(n) for n in (1, 999_999, 1_000_000, 2_100_000, 6_109_840, 10**9)] == [
        1.0,
        1.0,
        2.0,
        4.0,
        8.0,
        8.0,
    ]
    state = opened(monkeypatch, [True])
    assert all(p.preview_lod == rates.PREVIEW_LOD_PX for p in state.panes)  # the bundled scene: 1 px
    state.panes[0].preview_lod = 32.0  # where a large scene's previews had gone
    sizes = []
    monkeypatch.setattr(state_module, "first_preview_lod", lambda n: sizes.append(n) or 8.0)
    loaded(state)  # opened again: as a scene of 6 M splats would be
    assert sizes and sizes[0] == state.scene.num_splats
    assert all(p.preview_lod == 8.0 for p in state.panes)


def test_preview_lod_adapts_within_its_bounds():
    tau = rates.PREVIEW_LOD_PX
    for _ in range(20):
        tau = rates.preview_lod(tau, 500.0)
    assert tau == rates.MAX_PREVIEW_LOD
    assert rates.preview_lod(tau, 0.6 * rates.PREVIEW_MS) == tau  # within budget: kept
    for _ in range(20):
        tau = rates.preview_lod(tau, 1.0)
    assert tau == rates.PREVIEW_LOD_PX


def test_pane_lod_setting_is_normalised():
    assert PaneSettings(lod=-3).normalised().lod == 0.0
    assert PaneSettings(lod=1e9).normalised().lod == 64.0
    assert PaneSettings(lod="x").normalised().lod == 0.0
    state = AppState(AppSettings())
    state.set_pane(0, lod=2.5)
    assert state.settings_for(0, "a").lod == 2.5
    state.set_pane(0, lod=0.0)
    assert state.settings_for(0, "a").lod is None


def test_the_hierarchy_build_begins_once_every_pane_shows_the_scene(monkeypatch):
    started = []
    monkeypatch.setattr(loading, "start_lod", started.append)
    state = AppState(AppSettings())
    state.set_pane_count(2)
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    loaded(state)
    panes = PaneRenders(state, FakeWorker(), standalone_context())
    try:
        first = state.scene
        panes.poll()
        state.panes[0].parts["a"].job = object()
        panes.poll()
        assert started == []  # one pane of two shows the scene
        state.panes[1].parts["a"].job = object()
        panes.poll()
        panes.poll()
        assert started == [first]  # once
        loaded(state)  # another scene: its own build, after its own pictures
        panes.poll()
        assert started == [first] and state.scene is not first
        state.lod_due = time.perf_counter()  # its wait is over: the build begins without pictures
        panes.poll()
        assert started == [first, state.scene]
        loaded(state)
        replaced = state.scene
        loaded(state)  # replaced before its pictures or its wait's end: it starts no build
        state.lod_due = time.perf_counter()
        panes.poll()
        assert started[2:] == [state.scene] and state.scene is not replaced
    finally:
        panes.release()


def test_the_hierarchy_builds_in_a_thread_at_the_lowest_priority(monkeypatch):
    built, scene = [], gb.load(gb.DEFAULT_SCENE)
    linux = sys.platform.startswith("linux")  # where a thread has a niceness of its own

    def record(s):
        nice = os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) if linux else None
        built.append((s, threading.current_thread().name, nice))

    monkeypatch.setattr(loading, "hierarchy_for", record)
    loading.start_lod(scene)
    t0 = time.time()
    while not built:
        assert time.time() - t0 < 30
        time.sleep(0.01)
    assert built == [(scene, "gbviewer-lod", loading.LOD_NICE if linux else None)]


def test_a_scene_opened_is_built_for_at_the_latest_after_the_wait(monkeypatch):
    """The deadline `PaneRenders.poll` starts the build at without pictures: FIRST_PICTURES_WAIT_S (read when the
    scene opens) after it opened; none for a scene carrying wsr / duplex data (level of detail refuses it)."""
    monkeypatch.setattr(loading, "FIRST_PICTURES_WAIT_S", 37.0)
    state = AppState(AppSettings())
    t0 = time.perf_counter()
    loaded(state)
    assert t0 + 37.0 <= state.lod_due <= time.perf_counter() + 37.0
    s = state.scene
    oit = gb.Scene(s.means, s.scales, s.quats, s.opacities, s.sh, oit=OitData(weight_background=1.0))

    class Done:
        def done(self):
            return True

        def poll(self):
            return loading.LoadResult(Path("oit.ply"), scene=oit)

    state.loader = Done()
    assert state.poll_loader() == Path("oit.ply") and state.scene is oit and state.lod_due is None
