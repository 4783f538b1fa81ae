"""The first picture of a large scene: each pane's first request is a preview (the hierarchy's cut, or the scene's
sparse stand-in while the hierarchy is not there), the full frame is asked for once it is shown and refines over
it; each pane says what it waits for until its first tiles; the hierarchy builds at the lowest priority and no
preview waits for it (a build held back until the panes are final, in the real window, delays none of them); it
begins once every pane shows its first picture."""

from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np
import pytest
from test_lod_previews import FakeWorker, opened
from test_state import loaded
from window_helpers import shot

import gbviewer as gb
from gbviewer.app import panes as panes_module
from gbviewer.app.frames import rates
from gbviewer.app.panes import PaneRenders
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads import loading
from gbviewer.app.threads.worker import RenderResult
from gbviewer.lod import cache, sparse
from gbviewer.render.glsl.context import standalone_context


@pytest.fixture
def large(monkeypatch, tmp_path):
    """The bundled scene counts as large: its first pictures are previews, its stand-in keeps 1 splat in 4; the
    hierarchy's cache in tmp_path."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    n = gb.load(gb.DEFAULT_SCENE).num_splats
    monkeypatch.setattr(rates, "FIRST_PREVIEW_SPLATS", n)
    monkeypatch.setattr(sparse, "STAND_IN_SPLATS", n // 4 + 1)
    return n


def test_stand_in_keeps_every_kth_splat_widened():
    scene = gb.load(gb.DEFAULT_SCENE)
    n = scene.num_splats
    k = sparse.stride(n, n // 5)
    made = sparse.stand_in(scene, n // 5)
    assert k == 6 and made.num_splats == -(-n // k) <= n // 5 and made.meta["stand_in"] == k
    np.testing.assert_array_equal(made.means, scene.means[::k])
    np.testing.assert_array_equal(made.sh, scene.sh[::k])
    np.testing.assert_allclose(made.scales, scene.scales[::k] * k ** (1 / 3), rtol=1e-6)
    assert sparse.stand_in(scene, n // 5) is made  # made once per scene
    assert sparse.stand_in(scene, n) is scene  # small enough as it is


def test_hierarchy_state_while_it_builds(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    scene = gb.load(gb.DEFAULT_SCENE)
    seen, real = [], cache.build
    monkeypatch.setattr(cache, "build", lambda s, rule: seen.append(cache.hierarchy_state(s)) or real(s, rule))
    assert cache.hierarchy_state(scene) == ""
    cache.hierarchy_for(scene)
    assert seen == ["building"] and cache.hierarchy_state(scene) == "ready"


def test_first_request_is_a_preview_then_the_full_frame_refines_over_it(monkeypatch, large):
    state = AppState(AppSettings())
    state.set_pane_count(2)
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    loaded(state)
    state.reset_camera()
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()  # even while the framing counts as a motion: nothing of the scene is on screen yet
        assert [(j.preview, j.stand_in, j.settings.lod, j.info["first"], j.info["preview"]) for j in worker.jobs] == [
            (True, True, None, True, rates.FIRST_PREVIEW)
        ] * 2
        assert panes.progress(0, "a").startswith("waiting for the render thread")
        for doing in ("building", "reading"):
            monkeypatch.setattr(panes_module, "hierarchy_state", lambda scene, doing=doing: doing)
            assert panes.progress(0, "a").endswith(f" · {doing} level of detail")
        monkeypatch.setattr(panes_module, "hierarchy_state", lambda scene: "")
        jobs = list(worker.jobs)
        for j in jobs:  # the render thread takes them
            j.started = time.perf_counter()
        assert f"rendering a preview {jobs[0].camera.width}x{jobs[0].camera.height} (1 splat in 4)" in panes.progress(
            0, "a"
        )
        state.last_move = 0.0
        panes.submit()
        assert worker.jobs == jobs  # the full frames wait for the previews
        frames = gb.get_renderer(sparse.stand_in(state.scene), "cpu").render_many(
            [(j.camera, j.settings) for j in jobs]
        )
        for j, frame in zip(jobs, frames):
            panes._take(RenderResult(j, frame, finished=time.perf_counter()))
        assert all(p.parts["a"].stage == "preview" for p in state.visible)
        w, h = state.panes[0].render_size
        assert panes.progress(0, "a") == f"preview shown; rendering {w}x{h} next"
        panes.submit()
        full = worker.jobs[2:]
        assert [(j.preview, j.stand_in, j.progressive, j.settings.lod) for j in full] == [
            (False, False, True, None)
        ] * 2
        assert (full[0].camera.width, full[0].camera.height) == state.panes[0].render_size
        assert full[0].underlay is frames[0].rgb  # the tiles refine over the preview
        assert panes.progress(0, "a").startswith("preview shown; waiting for the render thread")
        full[0].started = time.perf_counter()
        assert panes.progress(0, "a").startswith(f"preview shown; rendering {w}x{h} ")
        panes._take(
            RenderResult(
                full[0],
                None,
                stage="partial",
                partial=np.zeros((h, w, 3), np.float32),
                progress=0.1,
                finished=time.perf_counter(),
            )
        )
        assert panes.progress(0, "a") is None  # its tiles are on screen: the refining line
    finally:
        panes.release()


def test_moving_previews_draw_the_stand_in_until_the_hierarchy_is_there(monkeypatch, large):
    moving = [True]
    state = opened(monkeypatch, moving)
    for p in state.panes:  # something of the scene is on screen: no first preview
        p.parts["a"].job = object()
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        assert worker.jobs and all(
            j.preview and j.stand_in and j.settings.lod is None and not j.info["first"] for j in worker.jobs
        )
        assert cache.hierarchy_state(state.scene) == ""  # nobody asked for it: nothing waits for it
        cache.hierarchy_for(state.scene)
        state.controller.orbit(5.0, 0.0)
        worker.jobs.clear()
        panes.submit()
        assert worker.jobs and all(
            j.preview and not j.stand_in and j.settings.lod == state.panes[0].preview_lod for j in worker.jobs
        )
    finally:
        panes.release()


def test_previews_draw_the_cut_once_the_hierarchy_is_there(monkeypatch, large):
    state = loaded(AppState(AppSettings()))
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    cache.hierarchy_for(state.scene)
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        assert worker.jobs and all(
            j.preview and not j.stand_in and j.settings.lod == state.panes[0].preview_lod for j in worker.jobs
        )
        assert "splat in" not in panes.progress(0, "a") and "level of detail" not in panes.progress(0, "a")
    finally:
        panes.release()


def test_small_scenes_show_the_full_frame_first(monkeypatch):
    state = loaded(AppState(AppSettings()))
    state.layout(640, 480, 20, 26, (1.0, 1.0))
    worker = FakeWorker()
    panes = PaneRenders(state, worker, standalone_context())
    try:
        panes.submit()
        assert worker.jobs and all(not j.preview and j.progressive and not j.stand_in for j in worker.jobs)
    finally:
        panes.release()


@pytest.mark.display
def test_panes_get_pictures_while_the_hierarchy_build_is_held_back(xvfb, tmp_path, monkeypatch, large):
    """In the window: the build is held until the test lets it go (after both panes' final frames); meanwhile each
    pane says what it waits for, then shows a preview of the stand-in, then its full frame. The build begins once
    every pane has its first picture, at the lowest priority."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # (and no cached hierarchy: `large`)
    # the build's fallback (it starts after FIRST_PICTURES_WAIT_S without pictures) is not under test: on a loaded
    # machine the panes' first pictures can take longer than it
    monkeypatch.setattr(loading, "FIRST_PICTURES_WAIT_S", 120.0)
    release, building, priority = threading.Event(), threading.Event(), []
    real = cache.build
    viewer = []  # the app, once made

    def slow_build(scene, rule):
        if not viewer or scene is not viewer[0].state.scene:  # not this test's scene
            return real(scene, rule)
        if sys.platform.startswith("linux"):
            priority.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
        building.set()
        assert release.wait(120)
        return real(scene, rule)

    monkeypatch.setattr(cache, "build", slow_build)
    from gbviewer.app.window import ViewerApp

    app = ViewerApp(None, size=(1040, 700))
    viewer.append(app)
    try:
        s = app.state
        s.set_pane_count(2)
        for i, mode in enumerate(("scalar", "gaussian_blending")):
            s.set_pane(i, mode=mode, supersample=1, split=False, view="color", lod=0.0)
        lines: dict[str, list[str]] = {}
        stages: dict[str, list[str]] = {}
        t0 = time.time()
        while not (s.scene is not None and app.panes.all_current()):
            assert time.time() - t0 < 120, "the panes never finished"
            app.step()
            if any(p.parts["a"].stage == "" for p in s.visible):
                assert not building.is_set()  # the build waits for the panes' first pictures
            for p in s.visible:
                shown = p.parts["a"]
                if not stages.get(p.name) or stages[p.name][-1] != shown.stage:
                    stages.setdefault(p.name, []).append(shown.stage)
                if shown.stage in ("", "preview"):
                    lines.setdefault(p.name, []).extend(
                        i.full for i in app.placed if i.role == "message" and p.rect.x <= i.x < p.rect.x + p.rect.w
                    )
                if shown.stage == "preview" and p.name == "B" and "preview" not in stages["A"][:-1]:
                    shot(app, "first-picture-preview")
            time.sleep(0.01)
        app.step()  # takes the final frames (all_current counts the last tiles of the latest request)
        for p in s.visible:
            stages[p.name].append(p.parts["a"].stage)
        # the build began (its thread runs at the lowest priority and looks in the cache first: on a loaded machine it
        # can begin after the panes' final frames), and is held still
        assert building.wait(60) and not release.is_set()
        assert cache.hierarchy_state(s.scene) == "building"
        for name in ("A", "B"):
            assert stages[name][:2] == ["", "preview"] and stages[name][-1] == "final", stages
            said = lines[name]
            w, h = s.panes[0].render_size
            assert any(t.startswith(f"preview shown; rendering {w}x{h} next") for t in said), said
        assert all(p.parts["a"].job.settings.lod is None and not p.parts["a"].job.stand_in for p in s.visible)
        if priority:
            assert priority == [19]  # loading.LOD_NICE: below the render thread's
        release.set()
        t0 = time.time()
        while cache.hierarchy_state(s.scene) != "ready":
            assert time.time() - t0 < 60
            time.sleep(0.02)
        s.controller.orbit(10.0, 0.0)
        s.moved()
        for p in s.visible:  # measured: moving drops to a preview resolution
            p.ms_per_px = {k: 1.0 for k in p.ms_per_px}
        app.step()
        asked = [p.asked["a"] for p in s.visible]
        assert all(j.preview and not j.stand_in and j.settings.lod is not None for j in asked)
    finally:
        release.set()
        app.close()
