"""The real viewer window under an Xvfb server the fixture starts (Mesa llvmpipe): what a person would check.

Inputs go through Dear ImGui's input queue (the same path as glfw's callbacks) or the methods the UI calls. Each
run keeps screenshots in tests/output/ (a CI artefact).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.rates import render_size
from gbviewer.app.settings import load_settings, settings_path
from gbviewer.app.views import decode_png16, visualize
from gbviewer.figure import to_uint8, upscale_nearest

pytestmark = pytest.mark.display

OUTPUT = Path(__file__).resolve().parents[1] / "output"
GBVIEWER_ROOT = str(Path(gb.__file__).resolve().parents[1])  # subprocesses import the gbviewer under test
LABEL_BAND = 60  # pixels at the top of a pane that hold the label and the preview/rendering line


@pytest.fixture
def app(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.window import ViewerApp

    a = ViewerApp(None, size=(1040, 700))
    a.state.settings.show_info = False  # comparisons need the image without the stats lines; one test turns it on
    yield a
    a.close()


def shot(app, name: str) -> np.ndarray:
    """A screenshot through the app's own function, kept in tests/output/."""
    OUTPUT.mkdir(exist_ok=True)
    path = app.screenshot_window(OUTPUT / f"{name}.png")
    app.step()
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"))


def pane_pixels(img: np.ndarray, rect) -> np.ndarray:
    return img[rect.y:rect.y + rect.h, rect.x:rect.x + rect.w]


def expected_pane(app, i: int, part: str = "a", view: str = "color") -> np.ndarray:
    """gb.render at the pane's render camera on the CPU (whatever the pane rendered on: the backends agree far within
    one level, and a glsl render here, in the thread of the window's context, would need the headless context made
    current beside it), nearest-upscaled to the pane."""
    p = app.state.panes[i]
    job = p.parts[part].job
    frame = gb.render(app.state.scene, job.camera, job.settings.mode, job.settings.supersample, "cpu",
                      debug=job.settings.debug)
    rgb, _ = visualize(frame, view)
    return upscale_nearest(to_uint8(rgb), p.rect.h, p.rect.w)


def agree(a: np.ndarray, b: np.ndarray, border: int = 1) -> float:
    """Fraction of pixels equal within 1 level, `border` pixels in from the edges (the hovered pane's outline)."""
    if border:
        a, b = a[:-border, border:-border], b[:-border, border:-border]
    return float((np.abs(a.astype(int) - b.astype(int)).max(axis=2) <= 1).mean())


def wait(app):
    assert app.wait_rendered(180), "the panes did not finish rendering"


def test_panes_show_the_renders_at_their_resolution_and_labels(app):
    app.state.set_pane_count(2)
    app.state.settings.layout = "row"
    app.state.set_pane(0, mode="scalar", supersample=1, split=False, view="color")
    app.state.set_pane(1, mode="gaussian_blending", supersample=1, split=False, view="color")
    app.state.set_rate(1 / 8)
    wait(app)
    img = shot(app, "viewer-x1_8")
    sizes = []
    for i in range(2):
        p = app.state.panes[i]
        cam = p.parts["a"].job.camera
        assert (cam.width, cam.height) == render_size(p.rect.w, p.rect.h, 1 / 8) == p.render_size
        sizes.append((cam.width, cam.height))
        got = pane_pixels(img, p.rect)
        want = expected_pane(app, i)
        assert agree(got[LABEL_BAND:], want[LABEL_BAND:]) > 0.995
        assert got[LABEL_BAND:].std() > 10, "pane is blank"
        # the label is drawn on the image: white text on a dark box where the render is dark
        white = lambda a: int((a[4:26, 4:200].min(axis=2) > 200).sum())  # noqa: E731
        assert white(got) > 30 + white(want)
    a, b = (pane_pixels(img, app.state.panes[i].rect)[LABEL_BAND:].astype(int) for i in range(2))
    h, w = min(a.shape[0], b.shape[0]), min(a.shape[1], b.shape[1])
    assert np.abs(a[:h, :w] - b[:h, :w]).mean() > 2, "scalar and gaussian_blending look the same at x1/8"

    app.state.set_rate(1 / 2)  # the sampling rate changes the render resolution
    wait(app)
    img = shot(app, "viewer-x1_2")
    for i in range(2):
        p = app.state.panes[i]
        cam = p.parts["a"].job.camera
        assert (cam.width, cam.height) == render_size(p.rect.w, p.rect.h, 1 / 2)
        assert cam.width > 3 * sizes[i][0]
        assert agree(pane_pixels(img, p.rect)[LABEL_BAND:], expected_pane(app, i)[LABEL_BAND:]) > 0.995


def test_split_view_loupe_help_debug_views_and_pane_screenshot(app, tmp_path):
    app.state.set_pane_count(1)
    app.state.set_pane(0, mode="scalar", split=True, split_mode="gaussian_blending", split_pos=0.5, view="color")
    app.state.set_rate(1 / 4)
    wait(app)
    img = shot(app, "viewer-split")
    p = app.state.panes[0]
    got = pane_pixels(img, p.rect)
    half = p.rect.w // 2
    left, right = expected_pane(app, 0, "a"), expected_pane(app, 0, "b")
    assert agree(got[LABEL_BAND:, :half - 6], left[LABEL_BAND:, :half - 6]) > 0.995
    assert agree(got[LABEL_BAND:, half + 6:], right[LABEL_BAND:, half + 6:]) > 0.995

    # drag the divider with the mouse
    from imgui_bundle import imgui

    io = imgui.get_io()
    r = p.rect
    io.add_mouse_pos_event(r.x + r.w / 2, r.y + r.h / 2)
    app.step()
    io.add_mouse_button_event(0, True)
    app.step()
    io.add_mouse_pos_event(r.x + r.w * 0.25, r.y + r.h / 2)
    app.step()
    io.add_mouse_button_event(0, False)
    app.step()
    assert app.state.settings.panes[0].split_pos == pytest.approx(0.25, abs=0.01)

    # loupe under the cursor, help overlay through F1, information overlay
    app.state.settings.loupe = True
    app.state.settings.show_info = True
    io.add_mouse_pos_event(r.x + r.w * 0.6, r.y + r.h * 0.6)
    io.add_key_event(imgui.Key.f1, True)
    app.step()
    io.add_key_event(imgui.Key.f1, False)
    app.run_frames(2)
    assert app.state.show_help and app.state.hover is not None and app.state.hover[0] == 0
    img2 = shot(app, "viewer-loupe-help")
    assert np.abs(img2.astype(int) - img.astype(int)).mean() > 1
    app.state.show_help = False

    # pane screenshot: the render itself at 16 bits
    path = app.screenshot_pane(0, tmp_path / "pane.png")
    data = decode_png16(path.read_bytes())
    frame = app.state.panes[0].parts["a"].frame
    assert data.shape == frame.rgb.shape
    assert np.abs(data / 65535 - np.clip(frame.rgb, 0, 1)).max() < 1e-4

    # debug views
    app.state.set_pane(0, split=False, mode="gaussian_blending")
    for view in ("alpha", "transmittance", "window", "evals"):
        app.state.set_pane(0, view=view)
        wait(app)
        shown = app.state.panes[0].parts["a"]
        assert shown.view == view and shown.legend and "only" not in shown.legend
        assert shown.image.std() > 1
    shot(app, "viewer-window-size")


def test_four_panes_grid_camera_input_and_training_cameras(app, tmp_path):
    app.state.set_pane_count(4)
    app.state.settings.layout = "grid"
    app.state.set_rate(1 / 8)
    wait(app)
    rects = [p.rect for p in app.state.panes]
    assert rects[0].y == rects[1].y < rects[2].y == rects[3].y and rects[0].x == rects[2].x < rects[1].x
    img = shot(app, "viewer-grid")
    for i in range(4):
        assert agree(pane_pixels(img, rects[i])[LABEL_BAND:], expected_pane(app, i)[LABEL_BAND:]) > 0.995

    from imgui_bundle import imgui

    io = imgui.get_io()
    R0, d0 = app.state.controller.R.copy(), app.state.controller.distance
    r = rects[0]
    io.add_mouse_pos_event(r.x + 40, r.y + 80)
    app.step()
    io.add_mouse_button_event(0, True)
    app.step()
    for k in range(5):
        io.add_mouse_pos_event(r.x + 40 + 10 * k, r.y + 80)
        app.step()
    io.add_mouse_button_event(0, False)
    app.step()
    io.add_mouse_wheel_event(0, 2)
    app.step()
    assert np.abs(app.state.controller.R - R0).max() > 0.05 and app.state.controller.distance < d0
    app.state.reset_camera()
    assert app.state.controller.R == pytest.approx(R0)
    # training cameras from an opened cameras.json: snap to the first, step to the next
    cams = [gb.orbit_camera(app.state.scene, az, 10, width=320, height=240) for az in (0, 90)]
    entries = [{"id": k, "img_name": f"view{k}", "width": 320, "height": 240, "fx": c.fx, "fy": c.fy,
                "position": c.position.tolist(), "rotation": c.R.T.tolist()} for k, c in enumerate(cams)]
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(entries))
    app.state.open(path)
    assert len(app.state.cameras) == 2 and app.state.cam_index == 0
    assert app.state.controller.camera(320, 240).R == pytest.approx(cams[0].R)
    assert app.state.controller.camera(320, 240).t == pytest.approx(cams[0].t)
    press(app, imgui.Key.right_bracket)
    assert app.state.cam_index == 1 and app.state.controller.camera(320, 240).t == pytest.approx(cams[1].t)
    wait(app)
    shot(app, "viewer-training-camera")


def test_bad_file_keeps_the_scene_and_shows_the_error_then_settings_persist(app, tmp_path):
    app.state.set_rate(1 / 8)
    wait(app)
    scene = app.state.scene
    bad = tmp_path / "broken.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nend_header\n\x00")
    app.state.open(bad)
    t0 = time.time()
    while app.state.loader is not None and time.time() - t0 < 30:
        app.step()
    app.run_frames(2)
    assert app.state.scene is scene and "broken.ply" in app.state.load_error and "\n" not in app.state.load_error
    img = shot(app, "viewer-bad-file")
    panel = img[:, :340].astype(int)
    reddish = (panel[..., 0] > 200) & (panel[..., 1] < 150) & (panel[..., 2] < 140)
    assert reddish.sum() > 30, "the error is not shown in the window"
    p = app.state.panes[0]
    assert pane_pixels(img, p.rect)[LABEL_BAND:].std() > 10, "the previous scene is no longer shown"

    # settings persist across runs
    app.state.set_pane_count(3)
    app.state.settings.layout = "grid"
    app.state.set_pane(2, mode="analytic", supersample=2)
    app.close()
    saved = settings_path()
    assert saved.exists()
    s, warning = load_settings()
    assert warning == "" and s.pane_count == 3 and s.layout == "grid" and s.rate == 1 / 8
    assert s.panes[2].mode == "analytic" and s.panes[2].supersample == 2
    assert str(gb.DEFAULT_SCENE.resolve()) in s.recent


def press(app, key, shift: bool = False, frames: int = 1) -> None:
    from imgui_bundle import imgui

    io = imgui.get_io()
    if shift:
        io.add_key_event(imgui.Key.left_shift, True)
        io.add_key_event(imgui.Key.mod_shift, True)
    io.add_key_event(key, True)
    app.run_frames(frames)
    io.add_key_event(key, False)
    if shift:
        io.add_key_event(imgui.Key.left_shift, False)
        io.add_key_event(imgui.Key.mod_shift, False)
    app.step()


def test_keyboard_shortcuts(app, tmp_path):
    from imgui_bundle import imgui

    K = imgui.Key
    app.state.settings.screenshot_dir = str(tmp_path)
    app.state.set_rate(1.0)
    app.state.set_pane_count(2)
    app.run_frames(2)
    press(app, K.minus)
    assert app.state.settings.rate == 0.5
    press(app, K.equal)
    press(app, K.equal)
    assert app.state.settings.rate == 2
    press(app, K._0)
    assert app.state.settings.rate == 1
    press(app, K._3)
    assert app.state.settings.pane_count == 3
    layout = app.state.settings.layout
    press(app, K.g)
    assert app.state.settings.layout != layout
    loupe, info = app.state.settings.loupe, app.state.settings.show_info
    press(app, K.l)
    press(app, K.i)
    assert app.state.settings.loupe != loupe and app.state.settings.show_info != info
    io = imgui.get_io()
    r = app.state.panes[1].rect
    io.add_mouse_pos_event(r.x + r.w / 2, r.y + r.h / 2)
    app.step()
    mode = app.state.settings.panes[1].mode
    press(app, K.m)
    assert app.state.settings.panes[1].mode != mode
    press(app, K.m, shift=True)
    assert app.state.settings.panes[1].mode == mode
    press(app, K.v)
    assert app.state.settings.panes[1].split
    press(app, K.slash, shift=True)
    assert app.state.show_help
    press(app, K.escape)
    assert not app.state.show_help
    up = app.state.settings.up
    press(app, K.u)
    assert app.state.settings.up != up and app.state.controller.up == app.state.settings.up
    press(app, K.f)
    assert app.state.fly
    eye = app.state.controller.eye
    press(app, K.w, frames=5)
    assert (app.state.controller.eye - eye) @ app.state.controller.forward > 0
    press(app, K.f)
    assert not app.state.fly
    press(app, K.r)
    press(app, K.f12)
    assert len(list(tmp_path.glob("*-window-*.png"))) == 1
    app.wait_rendered(120)
    io.add_mouse_pos_event(r.x + r.w / 2, r.y + r.h / 2)
    app.step()
    press(app, K.f12, shift=True)
    assert len(list(tmp_path.glob("*-paneB-*.png"))) == 1


def test_orthographic_projection_key(app):
    """O switches the panes to an orthographic camera (the screenshot is kept: tests/output/viewer-orthographic.png);
    each pane shows gb.render at its orthographic camera; O again switches back."""
    from imgui_bundle import imgui

    app.state.set_pane_count(2)
    wait(app)
    press(app, imgui.Key.o)
    assert app.state.settings.projection == "orthographic"
    wait(app)
    img = shot(app, "viewer-orthographic")
    for i in (0, 1):
        assert app.state.panes[i].parts["a"].job.camera.orthographic
        got = pane_pixels(img, app.state.panes[i].rect)[LABEL_BAND:]
        assert agree(got, expected_pane(app, i)[LABEL_BAND:]) > 0.99
    press(app, imgui.Key.o)
    wait(app)
    assert not app.state.panes[0].parts["a"].job.camera.orthographic


def test_drop_a_file_glsl_backend_and_render_limit(app, tmp_path):
    dropped = tmp_path / "dropped.ply"
    shutil.copy(gb.DEFAULT_SCENE, dropped)
    app.state.set_pane_count(2)
    app.state.set_rate(1 / 8)
    app._on_drop(app.window, [str(dropped)])  # what glfw's drop callback calls
    wait(app)
    assert app.state.scene_path == dropped and app.state.settings.recent[0] == str(dropped.resolve())
    ok, why = app.worker.backend_status("glsl")
    if ok:
        app.state.settings.backend = "glsl"
        wait(app)
        for i in range(2):
            shown = app.state.panes[i].parts["a"]
            assert shown.job.backend == "glsl" and shown.frame.stats.backend == "glsl"
            ref = gb.render(app.state.scene, shown.job.camera, shown.job.settings.mode)
            assert np.abs(shown.frame.rgb - ref.rgb).max() < 5e-3
    else:
        assert why  # greyed out with a reason
    app.state.settings.backend = "cpu"
    app.state.set_pane(0, supersample=8)
    app.state.set_rate(8)
    app.run_frames(2)
    assert "limit" in app.state.panes[0].parts["a"].error
    app.state.set_rate(1 / 8)
    wait(app)
    assert app.state.panes[0].parts["a"].error == ""


def test_file_dialog_opens_the_chosen_file(app, tmp_path, monkeypatch):
    """File > Open goes through portable-file-dialogs (here answered by a stand-in zenity on PATH)."""
    chosen = tmp_path / "chosen.ply"
    shutil.copy(gb.DEFAULT_SCENE, chosen)
    fake = tmp_path / "bin" / "zenity"
    fake.parent.mkdir()
    fake.write_text(f"#!/bin/sh\necho {chosen}\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake.parent}:{os.environ['PATH']}")
    app.state.set_rate(1 / 8)
    app.open_dialog()
    assert app.dialogs.file_dialog is not None
    t0 = time.time()
    while (app.dialogs.file_dialog is not None or app.state.loader is not None) and time.time() - t0 < 60:
        app.step()
    assert app.state.scene_path == chosen


def test_built_in_browser_without_a_dialog_program(app, monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    app.open_dialog()
    assert app.dialogs.file_dialog is None and app.dialogs.browser is not None
    app.run_frames(2)
    shot(app, "viewer-browser")


def test_record_zoom_video_in_the_background(app, tmp_path):
    app.state.set_pane_count(2)
    app.state.set_rate(1 / 8)
    wait(app)
    job = app.state.record_video(frames=3, out=tmp_path / "zoom.mp4")
    t0 = time.time()
    while not job.finished() and time.time() - t0 < 180:
        app.step()  # the UI keeps running while the video renders
        time.sleep(0.02)
    app.step()
    assert job.error == "" and (tmp_path / "zoom.mp4").stat().st_size > 1000
    assert any("zoom.mp4" in m[1] for m in app.state.messages)
    job = app.state.record_video(frames=200, out=tmp_path / "cancelled.mp4")
    job.cancel(wait=60)
    assert job.finished() and not (tmp_path / "cancelled.mp4").exists()


def test_gbviewer_command_opens_the_window_and_exits_cleanly(xvfb, tmp_path):
    """`gbviewer` on a display: a window, and a clean exit when it is closed (here after a few frames)."""
    code = ("import glfw, sys\n"
            "from gbviewer.app import window\n"
            "orig = window.ViewerApp.step\n"
            "def step(self, poll=True):\n"
            "    orig(self, poll)\n"
            "    if self.frame_count >= 5 and self.state.scene is not None:\n"
            "        glfw.set_window_should_close(self.window, True)\n"
            "window.ViewerApp.step = step\n"
            "from gbviewer.cli import main\n"
            "sys.exit(main([]))\n")
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp_path / "cfg"), PYTHONPATH=GBVIEWER_ROOT)
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "cfg" / "gbviewer" / "settings.json").exists()
    assert not (tmp_path / "out").exists()  # the window opened: no fallback images


def test_cameras_from_the_command_line(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.window import ViewerApp

    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 60, 5, width=320, height=240)
    path = tmp_path / "cams.json"
    path.write_text(json.dumps([{"id": 0, "img_name": "v", "width": 320, "height": 240, "fx": cam.fx, "fy": cam.fy,
                                 "position": cam.position.tolist(), "rotation": cam.R.T.tolist()}]))
    a = ViewerApp(None, size=(800, 600), cameras=path)
    try:
        wait(a)
        assert len(a.state.cameras) == 1 and a.state.cam_index == 0
        assert a.state.controller.camera(320, 240).t == pytest.approx(cam.t)
    finally:
        a.close()


def test_no_display_falls_back_to_the_comparison_images(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = GBVIEWER_ROOT
    proc = subprocess.run([sys.executable, "-m", "gbviewer", "--width", "64", "--height", "48"], env=env,
                          cwd=tmp_path, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert "no display" in proc.stdout
    assert (tmp_path / "out" / "comparison.png").exists()


def test_scene_switches_keep_one_texture_per_pane_part(app, tmp_path):
    """Opening a scene reuses the panes' textures: the window's live GL textures do not grow with scene switches."""
    from soak_viewer import gl_object_counts

    app.state.set_pane_count(2)
    app.state.set_pane(0, split=True)
    app.state.set_rate(1 / 8)
    wait(app)
    level = gl_object_counts()
    for k in range(4):
        copy = tmp_path / f"scene{k}.ply"  # a new Scene object each time
        shutil.copy(gb.DEFAULT_SCENE, copy)
        app.state.open(copy)
        wait(app)
        assert app.state.scene_path == copy
    assert gl_object_counts() == level and len(app.panes._textures) == 3


def test_bad_file_and_new_scene_while_a_load_and_renders_are_in_flight(app, tmp_path):
    app.state.set_pane_count(3)
    app.state.set_rate(1 / 4)
    wait(app)
    scene = app.state.scene
    good, bad = tmp_path / "good.ply", tmp_path / "bad.ply"
    shutil.copy(gb.DEFAULT_SCENE, good)
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\nproperty float x\n"
                    b"end_header\n" + bytes(16))
    app.state.controller.orbit(40, 5)  # renders in flight
    app.state.moved()
    app.step()
    app.state.open(good)
    app.state.open(bad)  # replaces the load of good.ply before it finished
    t0 = time.time()
    while app.state.loader is not None and time.time() - t0 < 60:
        app.step()
    errors = [m for m in app.state.messages if m[2] == "error"]
    assert len(errors) == 1 and "bad.ply" in errors[0][1] and app.state.scene is scene
    app.state.controller.orbit(-40, 0)
    app.state.moved()
    app.step()
    app.state.open(good)  # while the panes render the previous scene
    wait(app)
    assert app.state.scene_path == good and app.state.scene is not scene
    assert all(app.state.panes[i].parts["a"].job.scene is app.state.scene for i in range(3))
