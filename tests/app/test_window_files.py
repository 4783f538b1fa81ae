"""The real viewer window (Xvfb, Mesa llvmpipe) with files: a bad file, dropped files, the file dialog and the
built-in browser, settings that persist, the zoom video, scene switches while loads and renders are in flight."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np
import pytest
from window_helpers import LABEL_BAND, pane_pixels, shot, wait

import gbviewer as gb
from gbviewer.app.settings import load_settings, settings_path

pytestmark = pytest.mark.display


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
    error = app.state.panes[0].parts["a"].error
    assert error.kind == "too_large" and "limit" in error.text
    app.state.set_rate(1 / 8)
    wait(app)
    assert app.state.panes[0].parts["a"].error is None


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
    bad.write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\nproperty float x\n"
        b"end_header\n" + bytes(16)
    )
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


def test_camera_path_keys_export_import_and_path_video(app, tmp_path, monkeypatch):
    """Keyframes added from the view export as nerfstudio's camera_path.json, which the Open path imports (the
    view snaps to its first camera); Record then follows the path in the chosen codec."""
    from gbviewer.app.camera import path_keys
    from gbviewer.model.nerfstudio_paths import load_nerfstudio_path

    monkeypatch.setattr(path_keys, "PATH_FPS", 2.0)
    wait(app)
    app.state.add_keyframe()
    app.state.controller.orbit(40.0, 10.0)
    app.state.add_keyframe()
    out = app.state.export_camera_path(tmp_path / "camera_path.json")
    p = load_nerfstudio_path(out)
    assert len(p.keys) == 2 and len(p.frames) == 4 and p.seconds == path_keys.SECONDS_PER_KEY
    app.state.path_keys.clear()
    app.state.open(out)
    assert app.state.path_keys.source == out and len(app.state.path_keys) == 4
    np.testing.assert_allclose(app.state.controller.R, p.frames[0].R, atol=1e-6)
    app.run_frames(2)
    shot(app, "viewer-camera-path")
    app.state.video_codec = "vp9"
    job = app.state.record_video(out=tmp_path / "path.webm")
    t0 = time.time()
    while not job.finished() and time.time() - t0 < 180:
        app.step()
        time.sleep(0.02)
    assert job.error == "" and job.info.frames == 4 and job.info.width >= 480
    import imageio_ffmpeg

    meta = next(imageio_ffmpeg.read_frames(str(tmp_path / "path.webm")))
    assert meta["codec"] == "vp9" and imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "path.webm"))[0] == 4
