"""The panes' background and the dataset's lifecycle without a window: the backdrop estimated from a dataset's
photos (the median border colour) is the default for opaque photos, so that PSNR against photos of a grey backdrop
compares like with like; `--background` overrides it; Close dataset, a new scene dropping the dataset (kept aside
when the scene fits its cameras), `[ ]` snapping back to the view left, `R` restoring the default field of view, and
no jump in framing when the camera leaves a letterboxed view; pane A's photo view is what other panes' differences,
its info lines and its screenshot use."""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import replace

import numpy as np
import pytest
from dataset_builders import shots, write_cameras_json
from test_dataset import RATE, render_panes
from test_difference_views import settle
from test_state import loaded

import gbviewer as gb
from gbviewer.app.background import FIXED, PHOTOS
from gbviewer.app.dataset import bounds_fit_cameras
from gbviewer.app.difference.views import PaneAnalysis
from gbviewer.app.frames.views import encode_png16
from gbviewer.app.overlays.labels import stats_lines
from gbviewer.app.screenshots import save_pane
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.eval import camera_for_rate, ground_truth
from gbviewer.io.datasets import load_dataset
from gbviewer.io.datasets.backdrop import border, estimate_backdrop
from gbviewer.outputs import metrics
from gbviewer.outputs.differences import signed_difference

GREY = 0.6


@pytest.fixture(scope="module")
def grey_capture(bundled_scene, tmp_path_factory):
    """A cameras.json dataset whose opaque photos show the bundled scene on a grey backdrop."""
    views = [replace(s, rgb=s.rgb + (1 - s.alpha[..., None]) * GREY) for s in shots(bundled_scene, vary=False)]
    return write_cameras_json(tmp_path_factory.mktemp("grey"), views)


def opened(path, background=None, panes: int = 2) -> AppState:
    state = AppState(AppSettings(), background=background)
    state.set_pane_count(panes)
    state.layout(1240, 800, 20, 26)
    loaded(state)
    state.dataset.open(path)
    t0 = time.perf_counter()
    while state.dataset.dataset is None:
        assert time.perf_counter() - t0 < 60 and not state.dataset.error, state.dataset.error
        state.poll_dataset()
        time.sleep(0.01)
    return state


def test_border_ring():
    img = np.arange(5 * 6).reshape(5, 6, 1)
    assert len(border(img, 1)) == 2 * 6 + 2 * 3 and 14 not in border(img, 1)


def test_the_backdrop_is_the_median_border_colour(grey_capture):
    b = estimate_backdrop(load_dataset(grey_capture).views)
    assert b.opaque and b.photos == 8
    np.testing.assert_allclose(b.colour, (GREY,) * 3, atol=1 / 255)
    assert b.describe().startswith("0.60 0.60 0.60, the median border colour of 8 opaque photos")


@contextlib.contextmanager
def snapped(state):
    """The panes snapped to the dataset's second view and rendered, with their analysis settled: (analysis, view)."""
    an = PaneAnalysis(state)
    try:
        state.step_camera(1)
        render_panes(state)
        settle(an)
        yield an, state.dataset.view
    finally:
        an.stop()


def test_psnr_against_a_grey_backdrop_uses_it(grey_capture, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    state = opened(grey_capture)
    assert state.background_source == PHOTOS and "background from the photos: 0.60 0.60 0.60" in state.messages[-1][1]
    bg = state.background
    assert state.settings_for(1, "a").background == bg and state.settings.background == (0.0, 0.0, 0.0)
    state.set_rate(RATE)
    state.set_pane(1, mode="scalar", supersample=1)
    with snapped(state) as (an, view):
        cam, gt = camera_for_rate(view.camera, RATE), ground_truth(view, RATE)
        on_grey = metrics.psnr(gb.render(state.scene, cam, "scalar", background=bg).rgb, gt)
        on_black = metrics.psnr(gb.render(state.scene, cam, "scalar").rgb, gt)
        assert an.latest[(1, "a")].psnr == on_grey and on_grey > on_black + 3
        text, stale = an.fidelity_line((1, "a"))
        assert text == f"PSNR {on_grey:.2f} dB  SSIM {an.latest[(1, 'a')].ssim:.4f} vs photo (bg 0.60 0.60 0.60)"
        state.set_background((0.0, 0.0, 0.0))  # the panel's colour: back to black, the PSNR falls
        assert state.background_source == FIXED and state.settings_for(1, "a").background == (0.0, 0.0, 0.0)
        render_panes(state)
        settle(an)
        assert an.latest[(1, "a")].psnr == on_black


def test_a_given_background_is_kept_with_opaque_photos(grey_capture):
    state = opened(grey_capture, background=(1.0, 1.0, 1.0))
    assert state.background_source == FIXED and state.background == (1.0, 1.0, 1.0)
    state.use_photo_background()  # the panel's "from photos"
    assert state.background == state.dataset.backdrop.colour
    state.close_dataset()
    assert state.dataset.dataset is None and state.background == (1.0, 1.0, 1.0)
    assert state.messages[-1][1] == f"closed dataset {grey_capture.name}"


def test_a_new_scene_drops_the_dataset_and_keep_reopens_it(grey_capture):
    state = opened(grey_capture)
    d = state.dataset.dataset
    state.step_camera(1)
    loaded(state)  # the same scene again: its bounds fit the cameras, so it is set aside, not kept
    assert state.dataset.dataset is None and state.dataset.view is None and state.photo_camera() is None
    assert state.background_source == FIXED and "'Keep dataset'" in state.messages[-2][1]
    state.keep_dataset()
    assert state.dataset.dataset is d and state.dataset.set_aside is None
    lo, hi = state.scene.robust_bounds()
    cams = [v.camera for v in d.views]
    assert bounds_fit_cameras(lo, hi, cams) and not bounds_fit_cameras(lo + 1000, hi + 1000, cams)
    assert not bounds_fit_cameras(lo * 1e-4, hi * 1e-4 + 50, cams)


def test_snap_back_default_fov_and_no_jump_leaving_a_letterboxed_view(grey_capture):
    state = opened(grey_capture, panes=3)  # tall panes: the 130x100 photos letterboxed top and bottom
    state.reset_camera()
    default_fov = state.controller.fov_y_deg
    state.step_camera(1)
    state.step_camera(1)
    assert state.dataset.view.name == "v08"
    view = state.dataset.view
    state.layout(1240, 800, 20, 26)
    box, area = state.panes[0].rect, state.pane_areas[0]
    assert box.h < area.h - 10  # letterboxed
    state.controller.orbit(0.01, 0)  # a tiny orbit away: the same scale on screen, the full pane
    state.layout(1240, 800, 20, 26)
    assert state.photo_camera() is None and state.panes[0].rect == area
    cam = state.pane_camera(0)
    f_screen = view.camera.fy * box.h / view.camera.height  # the photo's focal length in window units
    assert math.isclose(cam.fy / state.settings.rate, f_screen, rel_tol=1e-3)
    state.step_camera(1)  # ]: back to the view left, not the next one
    assert state.dataset.view.name == "v08" and state.photo_camera() is not None
    assert state.messages[-1][1].startswith("test view v08")
    state.step_camera(1)
    assert state.dataset.view.name == "v00"  # at the view: the next one
    state.reset_camera()  # R: the default field of view, not the photo's
    assert state.controller.fov_y_deg == default_fov == state.settings.fov_y_deg


def test_pane_a_showing_the_photo_is_what_differences_and_screenshots_use(grey_capture, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    state = opened(grey_capture)
    state.set_rate(RATE)
    state.set_pane(0, view="photo")
    state.set_pane(1, mode="scalar", supersample=1, view="difference")
    with snapped(state) as (an, view):
        gt = ground_truth(view, RATE)
        b = state.panes[1].parts["a"]
        plane, legend = an.visualize((1, "a"), b.frame, "difference")
        assert legend == "B - A (photo v00)"  # against the photo pane A shows, not A's render
        np.testing.assert_array_equal(an.latest[(1, "a")].error, signed_difference(b.frame.rgb, gt))
        a = state.panes[0].parts["a"]
        a.view, a.legend = "photo", an.visualize((0, "a"), a.frame, "photo")[1]
        assert stats_lines(state.panes[0], "a") == []  # no render timings over the photo
        path = save_pane(state, 0, tmp_path / "a.png", colour=an.visualize)  # what is on screen: the photo
        assert path.read_bytes() == encode_png16(gt) != encode_png16(a.frame.rgb)
