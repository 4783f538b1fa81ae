"""The real viewer window under an Xvfb server the fixture starts (Mesa llvmpipe): what a person would check.

Inputs go through Dear ImGui's input queue (the same path as glfw's callbacks) or the methods the UI calls. Each
run keeps screenshots in tests/output/ (a CI artefact).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from window_helpers import LABEL_BAND, agree, expected_pane, pane_pixels, press, shot, wait

import gbviewer as gb
from gbviewer.app.frames.rates import render_size
from gbviewer.app.frames.views import decode_png16

pytestmark = pytest.mark.display


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
    assert agree(got[LABEL_BAND:, : half - 6], left[LABEL_BAND:, : half - 6]) > 0.995
    assert agree(got[LABEL_BAND:, half + 6 :], right[LABEL_BAND:, half + 6 :]) > 0.995

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
    entries = [
        {
            "id": k,
            "img_name": f"view{k}",
            "width": 320,
            "height": 240,
            "fx": c.fx,
            "fy": c.fy,
            "position": c.position.tolist(),
            "rotation": c.R.T.tolist(),
        }
        for k, c in enumerate(cams)
    ]
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
