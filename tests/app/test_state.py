"""The viewer's state and actions without a window: panes, rates, layout, the pane keys act on, opening scenes and
training cameras, messages."""

from __future__ import annotations

import json
import time

import pytest

import gbviewer as gb
from gbviewer.app.pane_state import RateMeter
from gbviewer.app.settings import MODE_NAMES, AppSettings
from gbviewer.app.state import AppState, is_cameras_file
from gbviewer.app.ui.layout import PANEL_W
from gbviewer.render import Mode


def laid_out(n: int = 2, layout: str = "row", scale=(1.0, 1.0)) -> AppState:
    s = AppState(AppSettings())
    s.set_pane_count(n)
    s.settings.layout = layout
    s.layout(1240, 800, 20, 26, scale)
    return s


def loaded(state: AppState) -> AppState:
    state.open(gb.DEFAULT_SCENE)
    t0 = time.time()
    while state.poll_loader() is None:
        assert time.time() - t0 < 30 and state.loader is not None, state.load_error
        time.sleep(0.01)
    return state


def test_rate_meter():
    m = RateMeter(span=2.0)
    for k in range(11):
        m.tick(100.0 + k * 0.1)
    assert m.rate(101.0) == pytest.approx(10.0)
    assert m.rate(200.0) == 0.0


def test_rate_actions_step_and_clamp():
    s = AppState(AppSettings())
    s.set_rate(100)
    assert s.settings.rate == 8
    s.step_rate(-1)
    assert s.settings.rate == 4
    s.set_rate(0.3)
    s.step_rate(+1)
    assert s.settings.rate == 0.5


def test_pane_count_and_layout():
    s = AppState(AppSettings())
    s.set_pane_count(9)
    assert s.settings.pane_count == 4 and len(s.visible) == 4
    s.set_pane_count(0)
    assert s.settings.pane_count == 1
    s.toggle_layout()
    assert s.settings.layout == "grid"
    s.toggle_layout()
    assert s.settings.layout == "row"


def test_layout_places_the_panes_right_of_the_panel_and_sizes_their_renders():
    s = laid_out(4, "grid", scale=(2.0, 2.0))
    s.set_rate(0.5)
    s.layout(1240, 800, 20, 26, (2.0, 2.0))
    v = s.viewport
    assert (v.x, v.y, v.w, v.h) == (PANEL_W, 20, 1240 - PANEL_W, 800 - 20 - 26)
    for p in s.visible:
        assert p.rect.x >= PANEL_W and p.rect.y >= 20
        assert p.render_size == (round(p.rect.w * 2 * 0.5), round(p.rect.h * 2 * 0.5))
        cam = s.pane_camera(p.index)
        assert (cam.width, cam.height) == p.render_size
        assert s.pane_at(p.rect.x + 1, p.rect.y + 1) == p.index
    assert s.pane_at(10, 100) is None


def test_keys_act_on_the_pane_under_the_cursor_else_the_first():
    s = laid_out(2)
    modes = [p.mode for p in s.settings.panes]
    s.next_mode(1)
    assert s.settings.panes[0].mode == MODE_NAMES[(MODE_NAMES.index(modes[0]) + 1) % len(MODE_NAMES)]
    s.hover = (1, 0.5, 0.5)
    s.next_mode(-1)
    assert s.settings.panes[1].mode == MODE_NAMES[MODE_NAMES.index(modes[1]) - 1]
    s.toggle_split()
    assert s.settings.panes[1].split and not s.settings.panes[0].split and s.parts(1) == ("a", "b")


def test_pane_settings_are_normalised_and_give_render_settings():
    s = AppState(AppSettings())
    s.set_pane(0, mode="gaussian_blending", supersample=20, view="window", split=True, split_mode="mip")
    ps = s.settings.panes[0]
    assert ps.supersample == 8
    a, b = s.settings_for(0, "a"), s.settings_for(0, "b")
    assert a.mode == Mode.GAUSSIAN_BLENDING and a.debug == "window" and a.supersample == 8
    assert b.mode == Mode.MIP and b.debug == "none"


def test_toggles_escape_fly_and_messages():
    s = AppState(AppSettings())
    s.toggle_help()
    s.toggle_fly()
    loupe, info = s.settings.loupe, s.settings.show_info
    s.toggle_loupe()
    s.toggle_info()
    assert s.show_help and s.fly and s.settings.loupe != loupe and s.settings.show_info != info
    eye = s.controller.eye
    s.fly_move(1, 0, 0, 0.5)
    assert s.moving and (s.controller.eye - eye) @ s.controller.forward > 0
    s.escape()
    assert not s.show_help and not s.fly
    eye = s.controller.eye
    s.fly_move(1, 0, 0, 0.5)  # not flying: nothing moves
    assert s.controller.eye == pytest.approx(eye)
    for k in range(10):
        s.message(f"m{k}", "warn")
    assert [m[1] for m in s.messages] == [f"m{k}" for k in range(4, 10)] and s.messages[-1][2] == "warn"


def test_projection_toggles_and_reaches_the_panes():
    s = laid_out(2)
    s.toggle_projection()
    assert s.settings.projection == s.controller.projection == "orthographic" and s.moving
    assert s.pane_camera(0).orthographic and s.pane_camera(1, preview=0.5).orthographic
    s.toggle_projection()
    assert s.settings.projection == "perspective" and not s.pane_camera(0).orthographic
    assert AppState(AppSettings(projection="orthographic")).controller.projection == "orthographic"


def test_up_axis_cycles():
    s = AppState(AppSettings())
    seen = [s.settings.up]
    for _ in range(4):
        s.next_up()
        seen.append(s.settings.up)
        assert s.controller.up == s.settings.up
    assert seen[-1] == seen[0] and len(set(seen)) == 4


def test_open_a_scene_then_training_cameras(tmp_path):
    s = loaded(laid_out(2))
    assert s.scene is not None and s.scene_path == gb.DEFAULT_SCENE
    assert s.settings.recent[0] == str(gb.DEFAULT_SCENE.resolve()) and s.needs_reset
    assert "opened" in s.messages[-1][1]
    s.step_camera(1)
    assert "no training cameras" in s.messages[-1][1] and s.messages[-1][2] == "warn"
    cam = gb.orbit_camera(s.scene, 40, 10, width=320, height=240)
    path = tmp_path / "cams.json"
    path.write_text(
        json.dumps(
            [
                {
                    "id": 0,
                    "img_name": "v",
                    "width": 320,
                    "height": 240,
                    "fx": cam.fx,
                    "fy": cam.fy,
                    "position": cam.position.tolist(),
                    "rotation": cam.R.T.tolist(),
                }
            ]
        )
    )
    assert is_cameras_file(path) and not is_cameras_file(gb.DEFAULT_SCENE)
    s.open(path)
    assert s.loader is None and s.cam_index == 0 and s.cameras_path == path
    assert s.controller.camera(320, 240).t == pytest.approx(cam.t)
    s.reset_camera()
    assert s.cam_index == -1
    (tmp_path / "bad.json").write_text("[1")
    s.open(tmp_path / "bad.json")
    assert "bad.json" in s.load_error and s.messages[-1][2] == "error" and len(s.cameras) == 1


def test_a_failed_load_keeps_the_scene(tmp_path):
    s = loaded(laid_out(1))
    scene = s.scene
    bad = tmp_path / "broken.ply"
    bad.write_bytes(b"ply\nformat nonsense\n")
    s.open(bad)
    t0 = time.time()
    while s.loader is not None and time.time() - t0 < 30:
        assert s.poll_loader() is None
        time.sleep(0.01)
    assert s.scene is scene and "broken.ply" in s.load_error and s.load_error_short.startswith("broken.ply")
