"""The dataset's photo in the real window (Xvfb, Mesa llvmpipe): `ViewerApp(scene, data=...)`, `]` snaps to the first
test view, pane A shows the photo at x1/4 (read back from the window: the ground truth, nearest-upscaled), the other
panes carry their PSNR/SSIM against it; `gbviewer SCENE --data DATASET` opens the window with the dataset.
Screenshots are kept in tests/output/."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from test_difference_window import wait_analysed
from window_helpers import GBVIEWER_ROOT, LABEL_BAND, agree, pane_pixels, press, shot, wait

import gbviewer as gb
from gbviewer.app.overlays import labels as overlays
from gbviewer.eval import camera_for_rate, ground_truth
from gbviewer.outputs import metrics
from gbviewer.outputs.figure import to_uint8, upscale_nearest

pytestmark = pytest.mark.display
RATE = 0.25


def untied(pixels: int, texels: int) -> np.ndarray:
    """Indices of the pixels whose centre does not fall on a boundary between two texels (an image of `texels`
    nearest-upscaled to `pixels`): at a tie the GPU and `upscale_nearest` may round to either side."""
    centres = (np.arange(pixels) + 0.5) * texels / pixels
    return np.nonzero(np.abs(centres - np.round(centres)) > 1e-6)[0]


@pytest.fixture
def photo_app(xvfb, capture, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    from gbviewer.app.window import ViewerApp

    a = ViewerApp(gb.DEFAULT_SCENE, size=(1280, 720), data=capture)
    a.state.settings.show_info = False
    yield a
    a.close()


def test_photo_pane_beside_scalar_and_gaussian_blending(photo_app):
    from imgui_bundle import imgui

    app, state = photo_app, photo_app.state
    state.set_pane_count(3)
    state.settings.layout = "row"
    state.set_pane(0, mode="scalar", supersample=1, view="photo", split=False)
    state.set_pane(1, mode="scalar", supersample=1, view="color", split=False)
    state.set_pane(2, mode="gaussian_blending", supersample=1, view="color", split=False)
    state.set_rate(RATE)
    wait(app)
    t0 = time.perf_counter()
    while state.dataset.dataset is None:
        assert time.perf_counter() - t0 < 60 and not state.dataset.error, state.dataset.error
        app.step()
    before = shot(app, "viewer-photo-before")  # not snapped: pane A shows its render, saying why
    assert state.panes[0].parts["a"].legend == "photo: snap to a dataset view ([ ] or the Dataset list)"
    imgui.get_io().add_mouse_pos_event(-100, -100)  # off the panes: no hover outline on them
    press(app, imgui.Key.right_bracket)  # ]: the first test view
    view = state.dataset.view
    assert view.name == "v00.png"
    wait(app)
    wait_analysed(app)
    img = shot(app, "viewer-photo-x1_4")
    gt = ground_truth(view, RATE)
    cam = camera_for_rate(view.camera, RATE)
    a = state.panes[0]
    assert a.parts["a"].legend == "photo v00.png  x1/4  32x25"
    assert abs(a.rect.w / a.rect.h - 32 / 25) < 0.02  # letterboxed to the photo's aspect
    expected = upscale_nearest(to_uint8(gt), a.rect.h, a.rect.w)
    got = pane_pixels(img, a.rect)
    rows, cols = untied(a.rect.h, 25), untied(a.rect.w, 32)
    rows = rows[rows >= LABEL_BAND]  # under the label
    assert agree(got[rows][:, cols], expected[rows][:, cols]) > 0.995
    assert agree(got[LABEL_BAND:], pane_pixels(before, a.rect)[LABEL_BAND:]) < 0.9  # not what it showed before
    # the panes render gaussian_blending at the fast precision (the viewer's default), and say so
    for i, mode, spec in ((1, "scalar", "scalar"), (2, "gaussian_blending fast", "gaussian_blending+fast")):
        p = state.panes[i]
        assert (p.parts["a"].job.camera.width, p.parts["a"].job.camera.height) == (32, 25)
        assert overlays.pane_label(app, p, "a") == f"{p.name}  {mode}  x1/4  32x25"
        assert abs(p.rect.w / p.rect.h - 32 / 25) < 0.02
        psnr = metrics.psnr(gb.render(state.scene, cam, spec, background=state.background).rgb, gt)
        text, stale = app.analysis.fidelity_line((i, "a"))  # on the photos' backdrop: black, as their borders
        assert not stale and text.startswith(f"PSNR {psnr:.2f} dB") and text.endswith("vs photo (bg 0.00 0.00 0.00)")
        line = next(i for i in app.placed if i.full == text)  # the pane's message line: white text on its dark box
        label = img[round(line.y) : round(line.y + line.h), round(line.x) : round(line.x + line.w)]
        assert (label.min(axis=2) > 200).sum() > 30
    assert app.analysis.fidelity_line((0, "a")) is None


def test_gbviewer_scene_data_opens_the_window_with_the_dataset(xvfb, capture, tmp_path):
    """`gbviewer SCENE --data DATASET`: the window opens with the dataset's views (closed once it is in)."""
    code = (
        "import glfw, sys\n"
        "from gbviewer.app import window\n"
        "orig = window.ViewerApp.step\n"
        "def step(self, poll=True):\n"
        "    orig(self, poll)\n"
        "    d = self.state.dataset\n"
        "    if self.state.scene is not None and d.loader is None:\n"
        "        print('views', len(d.dataset.views) if d.dataset else d.error, d.images)\n"
        "        glfw.set_window_should_close(self.window, True)\n"
        "window.ViewerApp.step = step\n"
        "from gbviewer.cli import main\n"
        f"sys.exit(main([{str(gb.DEFAULT_SCENE)!r}, '--data', {str(capture)!r}, '--images', 'images']))\n"
    )
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp_path / "cfg"), PYTHONPATH=GBVIEWER_ROOT)
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=180
    )
    assert proc.returncode == 0, proc.stderr
    assert "views 9 images" in proc.stdout
    assert not (tmp_path / "out").exists()  # the window opened: no fallback images
    np.testing.assert_equal(sorted(p.name for p in capture.iterdir()), ["images", "sparse"])  # nothing written there


def test_open_dataset_through_the_folder_dialog_and_the_built_in_browser(photo_app, capture, tmp_path, monkeypatch):
    """Open dataset... asks the system's folder dialog (here a stand-in zenity on PATH) or, without one, the built-in
    browser choosing folders; the folder chosen loads in the background."""
    from gbviewer.app.panel.dataset import open_dataset_dialog

    app, ds = photo_app, photo_app.state.dataset
    fake = tmp_path / "bin" / "zenity"
    fake.parent.mkdir()
    fake.write_text(f"#!/bin/sh\necho {capture}\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake.parent}:{os.environ['PATH']}")
    while ds.loader is not None:  # the dataset of the command line
        app.step()
    ds.dataset = None
    open_dataset_dialog(app.state, app.dialogs)
    assert app.dialogs.folder_dialog is not None
    t0 = time.perf_counter()
    while (app.dialogs.folder_dialog is not None or ds.loader is not None) and time.perf_counter() - t0 < 60:
        app.step()
    assert ds.dataset is not None and ds.dataset.root == capture
    monkeypatch.setenv("PATH", "/nonexistent")
    open_dataset_dialog(app.state, app.dialogs)
    b = app.dialogs.browser
    assert app.dialogs.folder_dialog is None and b is not None and b["dir"] == capture.parent
    app.run_frames(2)
    shot(app, "viewer-dataset-browser")
    app.dialogs._choose(capture)  # its "Open capture0" button
    assert app.dialogs.browser is None and ds.loader is not None and ds.loader.path == capture
