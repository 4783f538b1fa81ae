"""The viewer's training dataset without a window: loaded off the UI thread into the state (a bad one is one status
line, the scene and the open dataset kept), its views listed by split and name, snapping to one (every pane then
renders the photo's camera at the rate, letterboxed to its aspect), the photo view (the ground truth at the rate) and
every other pane's PSNR/SSIM against it, unavailable with a note once the camera leaves the view."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
from test_difference_views import settle
from test_state import laid_out, loaded

import gbviewer as gb
from gbviewer.app import dataset as app_dataset
from gbviewer.app.difference.views import PaneAnalysis
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads.worker import RenderJob
from gbviewer.app.ui.layout import Rect, fit_aspect
from gbviewer.eval import camera_for_rate, ground_truth
from gbviewer.model.camera import camera_key
from gbviewer.outputs import metrics

RATE = 0.25


def wait_dataset(state: AppState, timeout: float = 60.0) -> None:
    t0 = time.perf_counter()
    while state.dataset.loader is not None:
        assert time.perf_counter() - t0 < timeout, "the dataset did not load"
        state.dataset.poll()
        time.sleep(0.01)


def with_dataset(path: Path, panes: int = 2) -> AppState:
    state = loaded(laid_out(panes))
    state.dataset.open(path)
    wait_dataset(state)
    assert state.dataset.dataset is not None, state.dataset.error
    return state


def same_camera(a: gb.Camera, b: gb.Camera) -> bool:
    return camera_key(a) == camera_key(b)


def render_panes(state: AppState) -> None:
    """Each visible pane shows its final frame at the camera it renders with now (what panes.PaneRenders does)."""
    for p in state.visible:
        cam, settings = state.pane_camera(p.index), state.settings_for(p.index, "a")
        shown = p.parts["a"]
        shown.frame = gb.get_renderer(state.scene).render(cam, settings)
        shown.job = RenderJob(
            (p.index, "a"), state.scene, cam, settings, info={"preview": 1.0, "rate": state.settings.rate}
        )
        shown.stage = "final"
    state.last_move = 0.0  # at rest


def test_fit_aspect_letterboxes_a_pane():
    assert fit_aspect(Rect(10, 20, 400, 100), 2.0) == Rect(110, 20, 200, 100)
    assert fit_aspect(Rect(10, 20, 100, 400), 0.5) == Rect(10, 120, 100, 200)
    assert fit_aspect(Rect(0, 0, 130, 100), 1.3) == Rect(0, 0, 130, 100)


def test_the_dataset_loads_off_the_ui_thread(capture, monkeypatch):
    release, seen, load = threading.Event(), {}, app_dataset.load_dataset

    def slow_load(path, images):
        seen["thread"], seen["images"] = threading.current_thread().name, images
        release.wait(10)
        return load(path, images)

    monkeypatch.setattr(app_dataset, "load_dataset", slow_load)
    state = AppState(AppSettings())
    state.dataset.open(capture, "images")
    assert state.dataset.poll() is None and state.dataset.loader is not None  # returned at once, still loading
    release.set()
    wait_dataset(state)
    assert seen == {"thread": "gbviewer-dataset", "images": "images"}
    d = state.dataset.dataset
    assert len(d.views) == 9 and [v.name for v in d.views if v.split == "test"] == ["v00.png", "v08.png"]
    assert state.messages[-1][1].startswith(f"dataset {capture.name}: 9 views (2 test, colmap)")


def test_a_bad_dataset_is_one_status_line_and_keeps_the_scene_and_the_dataset(capture, tmp_path):
    state = with_dataset(capture)
    scene, data = state.scene, state.dataset.dataset
    (tmp_path / "empty").mkdir()
    for bad in (tmp_path / "empty", tmp_path / "missing"):
        state.dataset.open(bad)
        wait_dataset(state)
        text, level = state.messages[-1][1:]
        assert level == "error" and "\n" not in text and text.startswith(f"dataset not opened: {bad}")
        assert state.scene is scene and state.dataset.dataset is data and str(bad) in state.dataset.error


def test_snapping_renders_the_photo_camera_at_the_rate_letterboxed(capture):
    state = with_dataset(capture)
    state.set_rate(RATE)
    assert state.photo_camera() is None
    state.step_camera(1)  # ]: the first listed (test) view
    view = state.dataset.view
    assert view.name == "v00.png" and state.settings.projection == "perspective"
    want = camera_for_rate(view.camera, RATE)  # 32x25: the ragged edge of 130x100 cropped, then 4x coarser
    state.layout(1240, 800, 20, 26)
    for p in state.visible:
        assert same_camera(state.pane_camera(p.index), want) and p.render_size == (32, 25)
        assert abs(p.rect.w / p.rect.h - 32 / 25) < 0.02  # letterboxed to the photo
    assert same_camera(state.pane_camera(0, 0.5), want.at_sampling_rate(0.5))  # a preview while moving
    state.set_rate(2.0)  # no photo at x2: the photo's camera at that rate, still the same view
    assert same_camera(state.pane_camera(0), view.camera.at_sampling_rate(2.0))
    state.set_rate(RATE)
    state.step_camera(1)
    assert state.dataset.view.name == "v08.png"
    state.step_camera(1)
    assert state.dataset.view.name == "v00.png"  # wraps around the listed views
    state.dataset.set_split("train")
    state.dataset.name_filter = "5"
    assert [state.dataset.dataset.views[k].name for k in state.dataset.listed()] == ["v05.png"]
    state.step_camera(-1)
    assert state.dataset.view.name == "v05.png"
    state.dataset.name_filter = "nothing"
    state.step_camera(1)
    assert (
        state.dataset.view.name == "v05.png"
        and state.messages[-1][1] == "no train views named with 'nothing' in the dataset"
    )
    # leaving the view: the panes render the orbit camera at their own size again
    state.controller.orbit(30, 0)
    state.layout(1240, 800, 20, 26)
    assert state.photo_camera() is None and state.pane_camera(0).width == round(state.panes[0].rect.w * RATE)
    view, note = state.dataset.photo_for(state.pane_camera(0), RATE)
    assert view is None and note == "the camera left v05.png ([ ] to snap back)"


def test_photo_view_and_psnr_against_the_photo(capture, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    state = with_dataset(capture, panes=3)
    state.set_rate(RATE)
    state.set_pane(0, view="photo")
    state.set_pane(1, mode="scalar", supersample=1)
    state.set_pane(2, mode="gaussian_blending", supersample=1)
    an = PaneAnalysis(state)
    try:
        state.step_camera(1)
        view = state.dataset.view
        an.update()
        assert an.options.reference == "photo" and an.options.fidelity  # the snap chose the photo reference
        render_panes(state)
        settle(an)
        gt = ground_truth(view, RATE)
        shown = state.panes[0].parts["a"]
        rgb, legend = an.visualize((0, "a"), shown.frame, "photo")
        np.testing.assert_array_equal(rgb, gt)
        assert legend == "photo v00.png  x1/4  32x25" and an.fidelity_line((0, "a")) is None
        cam = camera_for_rate(view.camera, RATE)
        for i, mode in ((1, "scalar"), (2, "gaussian_blending+fast")):  # the viewer's precision
            p = metrics.psnr(gb.render(state.scene, cam, mode).rgb, gt)
            assert an.latest[(i, "a")].psnr == p
            text, stale = an.fidelity_line((i, "a"))
            assert text.startswith(f"PSNR {p:.2f} dB") and text.endswith("vs photo (bg 0.00 0.00 0.00)") and not stale
        assert list((tmp_path / "cache").rglob("*.npy"))  # the x1/4 photo is cached outside the dataset
        assert not list(capture.rglob("*.npy"))
        # the camera leaves the view: the labels go stale, then say why there is no photo
        state.controller.orbit(30, 0)
        state.moved()
        assert an.fidelity_line((1, "a"))[1] and "(stale)" in an.fidelity_line((1, "a"))[0]
        render_panes(state)
        an.update()
        note = "photo: the camera left v00.png ([ ] to snap back)"
        assert an.fidelity_line((1, "a")) == (note, True) and an.current()
        rgb, legend = an.visualize((0, "a"), shown.frame, "photo")
        assert rgb is shown.frame.rgb and legend == note
        # at x2 there is no photo
        state.step_camera(-1)
        state.set_rate(2.0)
        render_panes(state)
        an.update()
        assert an.fidelity_line((1, "a"))[0] == "photo: no photo at x2 (only x1/k, k up to the photo's size)"
    finally:
        an.stop()


def run_gbviewer(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(Path(gb.__file__).resolve().parents[1])
    return subprocess.run(
        [sys.executable, "-m", "gbviewer", *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=120
    )


def test_view_with_a_missing_dataset_is_one_line_exit_2(tmp_path):
    proc = run_gbviewer([str(gb.DEFAULT_SCENE), "--data", "nowhere"], tmp_path)
    assert proc.returncode == 2 and proc.stderr == "gbviewer: error: --data nowhere: no such file or folder\n"
