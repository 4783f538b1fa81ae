"""The viewer's pure logic, without a display: camera controller, rates, layout, loupe, settings, recent files."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app import logic
from gbviewer.app.logic import AppSettings, CameraController, PaneSettings
from gbviewer.app.worker import RenderJob, RenderWorker, SceneLoader
from gbviewer.render import RenderSettings

# ---- sampling rate --------------------------------------------------------------------------------------------------


def test_rate_steps_walk_every_step_both_ways():
    r, seen = 1 / 8, [1 / 8]
    for _ in range(10):
        r = logic.step_rate(r, +1)
        seen.append(r)
    assert seen[:7] == [1 / 8, 1 / 4, 1 / 2, 1, 2, 4, 8] and seen[-1] == 8
    r, down = 8.0, []
    for _ in range(8):
        r = logic.step_rate(r, -1)
        down.append(r)
    assert down[:6] == [4, 2, 1, 1 / 2, 1 / 4, 1 / 8] and down[-1] == 1 / 8


def test_rate_step_from_a_continuous_value_goes_to_the_neighbour_step():
    assert logic.step_rate(0.3, +1) == 0.5 and logic.step_rate(0.3, -1) == 0.25
    assert logic.step_rate(3.0, +1) == 4 and logic.step_rate(3.0, -1) == 2


def test_rate_slider_is_log2_snaps_to_steps_and_clamps():
    for r in logic.RATE_STEPS:
        assert logic.slider_to_rate(logic.rate_to_slider(r)) == pytest.approx(r)
    assert logic.slider_to_rate(-3.02) == 1 / 8  # snapped
    assert logic.slider_to_rate(0.5) == pytest.approx(2 ** 0.5)  # continuous in between
    assert logic.slider_to_rate(9) == 8 and logic.slider_to_rate(-9) == 1 / 8
    assert logic.clamp_rate(float("nan")) == 1.0 and logic.clamp_rate(100) == 8


def test_rate_labels():
    assert [logic.format_rate(r) for r in logic.RATE_STEPS] == ["x8", "x4", "x2", "x1", "x1/2", "x1/4", "x1/8"]
    assert logic.format_rate(0.27) == "x1/3.7" and logic.format_rate(2.5) == "x2.5"


def test_render_size_matches_camera_at_sampling_rate():
    cam = gb.Camera.look_at([0, 0, -3], [0, 0, 0], width=523, height=401)
    for r in (8, 1, 0.3, 1 / 8, 1 / 1000):
        c = cam.at_sampling_rate(r)
        assert logic.render_size(523, 401, r) == (c.width, c.height)


def test_preview_factor_only_while_moving_and_only_as_much_as_needed():
    assert logic.preview_factor(640 * 480, 1e-3, 60, moving=False) == 1.0
    assert logic.preview_factor(640 * 480, None, 60, moving=True) == 1.0
    assert logic.preview_factor(100 * 100, 1e-3, 60, moving=True) == 1.0  # 10 ms fits
    assert logic.preview_factor(640 * 480, 1e-3, 60, moving=True) == 0.25  # 307 ms -> 77 at 1/2, 19 at 1/4
    assert logic.preview_factor(4000 * 4000, 1e-3, 1, moving=True) == 0.125  # never below 1/8


# ---- layout, loupe, split -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n,layout,shape", [(1, "row", (1, 1)), (2, "row", (1, 2)), (4, "row", (1, 4)),
                                            (2, "grid", (1, 2)), (3, "grid", (2, 2)), (4, "grid", (2, 2))])
def test_pane_rects_tile_the_viewport_without_overlap(n, layout, shape):
    assert logic.grid_shape(n, layout) == shape
    rects = logic.pane_rects(100, 30, 1001, 700, n, layout, gap=4)
    assert len(rects) == n
    for r in rects:
        assert 100 <= r.x and r.x + r.w <= 1101 and 30 <= r.y and r.y + r.h <= 730
    for a in range(n):
        for b in range(a + 1, n):
            ra, rb = rects[a], rects[b]
            assert ra.x + ra.w <= rb.x or rb.x + rb.w <= ra.x or ra.y + ra.h <= rb.y or rb.y + rb.h <= ra.y
    widths = {r.w for r in rects}
    assert max(widths) - min(widths) <= 1
    rows, cols = shape
    assert rects[cols - 1].x + rects[cols - 1].w == 1101  # last column reaches the right edge
    assert rects[-1].y + rects[-1].h == 730 or rows == 1 and rects[0].y + rects[0].h == 730


def test_loupe_uv_is_centred_sized_by_zoom_and_clamped():
    u0, v0, u1, v1 = logic.loupe_uv(0.5, 0.5, 400, 200, radius_px=80, zoom=8)
    assert (u1 - u0) * 400 == pytest.approx(20) and (v1 - v0) * 200 == pytest.approx(20)
    assert (u0 + u1) / 2 == pytest.approx(0.5) and (v0 + v1) / 2 == pytest.approx(0.5)
    u0, v0, u1, v1 = logic.loupe_uv(0.0, 1.0, 400, 200, 80, 8)
    assert u0 == pytest.approx(0) and v1 == pytest.approx(1)


def test_split_parts():
    assert logic.split_parts(0.3) == ((0.0, 0.3), (0.3, 1.0))
    assert logic.split_parts(-1) == ((0.0, 0.0), (0.0, 1.0))


# ---- camera controller ----------------------------------------------------------------------------------------------


def framed(up: str = "-y") -> CameraController:
    c = CameraController(up=up)
    c.frame_bounds(np.array([-1.0, -1, -1]), np.array([1.0, 1, 1]))
    return c


def project(cam: gb.Camera, p) -> np.ndarray:
    x = cam.R @ np.asarray(p, float) + cam.t
    return np.array([cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy])


@pytest.mark.parametrize("up", ["-y", "+y", "+z", "-z"])
def test_default_framing_looks_at_the_centre_upright(up):
    c = framed(up)
    cam = c.camera(640, 480)
    assert project(cam, c.centre) == pytest.approx([320, 240], abs=1e-6)
    up_v = np.array(gb.camera.UP_AXES[up])
    above = project(cam, c.centre + 0.5 * up_v)
    assert above[1] < 240  # the scene's up is up on screen
    # same pose as gbviewer.orbit_camera for the same box
    assert np.linalg.norm(c.eye - c.centre) == pytest.approx(c.distance)


def test_orbit_turns_around_the_target_keeping_distance_and_upright():
    c = framed()
    t0, d0, eye0 = c.target.copy(), c.distance, c.eye
    right0 = c.R[0].copy()
    c.orbit(40, 0)
    assert c.target == pytest.approx(t0) and np.linalg.norm(c.eye - c.target) == pytest.approx(d0)
    assert (c.eye - eye0) @ right0 < 0  # drag right: the camera swings left, the scene turns right
    up = c.up_vector
    h0 = (eye0 - t0) @ up
    c.orbit(0, 40)
    assert (c.eye - c.target) @ up > h0  # drag down: look from higher up
    for _ in range(100):
        c.orbit(0, 50)  # never over the pole
    assert abs(c.R[2] @ up) < 0.996 and c.R[1] @ -up > 0
    assert np.allclose(c.R @ c.R.T, np.eye(3), atol=1e-9)


def test_look_turns_in_place():
    c = framed()
    eye0, right0 = c.eye, c.R[0].copy()
    c.look(30, 0)
    assert c.eye == pytest.approx(eye0)
    assert c.R[2] @ right0 > 0  # drag right: look right
    down = -c.up_vector
    f0 = c.R[2] @ down
    c.look(0, 20)
    assert c.R[2] @ down > f0  # drag down: look down


def test_pan_moves_the_point_under_the_cursor_with_it():
    c = framed()
    old = c.camera(640, 480)
    point = c.target.copy()  # on screen at the centre
    c.pan(50, -20, 480)
    new = c.camera(640, 480)
    assert new.R == pytest.approx(old.R)
    assert project(new, point) - project(old, point) == pytest.approx([50, -20], abs=1e-6)


def test_dolly_and_fly():
    c = framed()
    d0 = c.distance
    c.dolly(1)
    assert c.distance == pytest.approx(0.9 * d0)
    c.dolly(-2)
    assert c.distance == pytest.approx(d0 / 0.9)
    eye0, f = c.eye, c.forward
    c.fly(1, 0, 0, dt=0.5, speed=2.0)
    assert c.eye - eye0 == pytest.approx(f * c.radius)
    eye1 = c.eye
    c.fly(0, 0, 1, dt=1.0, speed=1.0)
    assert c.eye - eye1 == pytest.approx(c.up_vector * c.radius)


def test_fov_clamped_and_applied():
    c = framed()
    c.set_fov(200)
    assert c.fov_y_deg == 120
    c.set_fov(60)
    cam = c.camera(640, 480)
    assert logic.fov_of(cam) == pytest.approx(60)


def test_up_axis_change_keeps_eye_and_target_and_levels_the_view():
    c = framed("-y")
    eye, target = c.eye, c.target.copy()
    c.set_up("+z")
    assert c.eye == pytest.approx(eye) and c.target == pytest.approx(target)
    assert c.R[0] @ np.array([0, 0, 1.0]) == pytest.approx(0, abs=1e-9)  # no roll about +z
    with pytest.raises(ValueError):
        c.set_up("x")


def test_snap_to_a_training_camera_reproduces_it():
    c = framed()
    train = gb.Camera.look_at([2.0, -1, -3], [0.1, 0, 0], (0, -1, 0), 800, 600, 40.0)
    c.snap_to(train)
    cam = c.camera(800, 600)
    assert cam.R == pytest.approx(train.R) and cam.t == pytest.approx(train.t)
    assert cam.fy == pytest.approx(train.fy)
    c.orbit(10, 5)  # and the controls go on from there
    assert np.isfinite(c.R).all()


# ---- views, png16, settings -----------------------------------------------------------------------------------------


def test_debug_views():
    rgb = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    alpha = np.linspace(0, 1, 20, dtype=np.float32).reshape(4, 5)
    frame = gb.Frame(rgb, alpha, {}, {"evals": np.arange(20).reshape(4, 5)})
    img, legend = logic.visualize(frame, "alpha")
    assert img[..., 0] == pytest.approx(alpha) and legend
    img, _ = logic.visualize(frame, "transmittance")
    assert img[..., 1] == pytest.approx(1 - alpha)
    img, legend = logic.visualize(frame, "evals")
    assert img.shape == (4, 5, 3) and "19" in legend
    img, legend = logic.visualize(frame, "window")  # no window plane: colour, saying why
    assert img is rgb and "gaussian_blending" in legend
    frame.debug["window"] = np.full((4, 5, 2), 2.0, np.float32)
    img, legend = logic.visualize(frame, "window")
    assert img.shape == (4, 5, 3) and "2.00" in legend
    assert logic.visualize(frame, "color")[0] is rgb


def test_png16_round_trip_keeps_full_precision():
    rgb = np.random.default_rng(1).random((7, 9, 3)).astype(np.float32)
    data = logic.encode_png16(rgb)
    back = logic.decode_png16(data)
    assert back.shape == (7, 9, 3) and back.dtype == np.uint16
    assert np.abs(back / 65535 - rgb).max() < 1e-5
    from io import BytesIO

    from PIL import Image

    im = Image.open(BytesIO(data))  # a valid PNG for other readers too
    assert im.size == (9, 7)


def test_settings_round_trip_and_persistence(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    assert logic.settings_path() == tmp_path / "cfg" / "gbviewer" / "settings.json"
    s = AppSettings()
    s.pane_count, s.layout, s.rate, s.window = 3, "grid", 0.125, (1200, 800)
    s.panes[2] = PaneSettings("analytic", 4, "alpha", True, "mip", 0.3)
    s.recent = logic.add_recent([], tmp_path / "a.ply")
    path = logic.save_settings(s)
    assert path.exists()
    back, warning = logic.load_settings()
    assert warning == "" and back == s.normalised()
    assert back.panes[2] == PaneSettings("analytic", 4, "alpha", True, "mip", 0.3)


def test_bad_settings_fall_back_to_defaults_with_a_warning(tmp_path):
    p = tmp_path / "settings.json"
    p.write_text("{not json")
    s, warning = logic.load_settings(p)
    assert s == AppSettings() and "unreadable" in warning
    p.write_text(json.dumps({"pane_count": 99, "rate": -1, "layout": "spiral", "panes": [{"mode": "nope",
                             "supersample": 40, "view": "x", "extra": 1}], "up": "sideways", "window": "big",
                             "unknown_key": 1}))
    s, warning = logic.load_settings(p)
    assert warning == ""
    assert s.pane_count == 4 and s.rate == 1.0 and s.layout == "row" and s.up == "-y"
    assert s.panes[0] == PaneSettings("scalar", 8, "color") and len(s.panes) == 4


def test_recent_files_most_recent_first_without_duplicates(tmp_path):
    r: list[str] = []
    for name in ["a", "b", "a", "c"]:
        r = logic.add_recent(r, tmp_path / name)
    assert [p.rsplit("/", 1)[-1] for p in r] == ["c", "a", "b"]
    for k in range(20):
        r = logic.add_recent(r, tmp_path / f"f{k}")
    assert len(r) == logic.MAX_RECENT


def test_shortcut_table_covers_the_keys_the_issue_names():
    keys = " ".join(k for k, _ in logic.SHORTCUTS)
    for k in ("F1", "?", "W A S D", "Q E", "R", "[ ]", "F12", "L", "V", "- =", "1 2 3 4", "Ctrl+O"):
        assert k in keys


def test_display_detection():
    assert logic.has_display_env({})[0] is False and "DISPLAY" in logic.has_display_env({})[1]
    assert logic.has_display_env({"DISPLAY": ":1"}) == (True, "")
    assert logic.has_display_env({"WAYLAND_DISPLAY": "wayland-0"})[0]


def test_rate_meter():
    m = logic.RateMeter(span=2.0)
    for k in range(11):
        m.tick(100.0 + k * 0.1)
    assert m.rate(101.0) == pytest.approx(10.0)
    assert m.rate(200.0) == 0.0


# ---- worker threads -------------------------------------------------------------------------------------------------


def test_worker_renders_latest_request_per_slot_and_drops_stale_ones(bundled_scene):
    w = RenderWorker()
    try:
        cam = gb.orbit_camera(bundled_scene, width=64, height=48)
        for k in range(5):  # five requests for one slot in a burst: at most the first and the last are rendered
            w.submit(RenderJob(("p", "a"), bundled_scene, cam.at_sampling_rate(1 + k / 10), RenderSettings(), "cpu",
                               {"k": k}))
        w.submit(RenderJob(("q", "a"), bundled_scene, cam, RenderSettings("gaussian_blending"), "cpu", {"k": 9}))
        results, t0 = [], time.time()
        while (w.busy() or not results) and time.time() - t0 < 60:
            results += w.results()
            time.sleep(0.01)
        results += w.results()
        ks = [r.job.info["k"] for r in results if r.job.slot == ("p", "a")]
        assert ks[-1] == 4 and len(ks) <= 2 and w.dropped >= 3
        assert [r.job.info["k"] for r in results if r.job.slot == ("q", "a")] == [9]
        last = [r for r in results if r.job.slot == ("p", "a")][-1]
        ref = gb.render(bundled_scene, last.job.camera)
        assert np.array_equal(last.frame.rgb, ref.rgb)
        assert w.backends_ready.wait(30) and w.backends["cpu"] == (True, "")
    finally:
        w.stop()


def test_worker_reports_errors_without_dying(bundled_scene):
    w = RenderWorker()
    try:
        cam = gb.orbit_camera(bundled_scene, width=32, height=24)
        w.submit(RenderJob(1, bundled_scene, cam, RenderSettings(), "no-such-backend"))
        w.submit(RenderJob(2, bundled_scene, cam, RenderSettings(), "cpu"))
        out, t0 = [], time.time()
        while len(out) < 2 and time.time() - t0 < 30:
            out += w.results()
            time.sleep(0.01)
        by = {r.job.slot: r for r in out}
        assert by[1].frame is None and "no-such-backend" in by[1].error
        assert by[2].frame is not None
    finally:
        w.stop()


def test_scene_loader_in_background(tmp_path):
    ld = SceneLoader(gb.DEFAULT_SCENE)
    t0 = time.time()
    while not ld.done() and time.time() - t0 < 30:
        time.sleep(0.01)
    res = ld.poll()
    assert res.error == "" and res.scene.num_splats > 0 and res.cameras is None
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat nonsense\n")
    ld = SceneLoader(bad)
    while not ld.done():
        time.sleep(0.01)
    err = ld.poll().error
    assert err and "\n" not in err and "bad.ply" in err


def test_scene_loader_picks_up_cameras_json_beside_the_scene(tmp_path):
    import shutil

    scene = tmp_path / "scene.ply"
    shutil.copy(gb.DEFAULT_SCENE, scene)
    cam = gb.Camera.look_at([0, 0, -3.0], [0, 0, 0], width=64, height=48)
    c2w = cam.R.T
    (tmp_path / "cameras.json").write_text(json.dumps([{"id": 0, "img_name": "v0", "width": 64, "height": 48,
                                                        "fx": cam.fx, "fy": cam.fy, "position": cam.position.tolist(),
                                                        "rotation": c2w.tolist()}]))
    ld = SceneLoader(scene)
    while not ld.done():
        time.sleep(0.01)
    res = ld.poll()
    assert res.cameras_path == tmp_path / "cameras.json" and len(res.cameras) == 1
    assert res.cameras[0].R == pytest.approx(cam.R) and math.isclose(res.cameras[0].fx, cam.fx)
