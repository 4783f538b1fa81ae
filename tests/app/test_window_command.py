"""`gbviewer` on a display opens the window (with --cameras) and exits cleanly; without one it writes the
comparison images."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from window_helpers import GBVIEWER_ROOT, wait

import gbviewer as gb

pytestmark = pytest.mark.display


def test_gbviewer_command_opens_the_window_and_exits_cleanly(xvfb, tmp_path):
    """`gbviewer` on a display: a window, and a clean exit when it is closed (here after a few frames)."""
    code = (
        "import glfw, sys\n"
        "from gbviewer.app import window\n"
        "orig = window.ViewerApp.step\n"
        "def step(self, poll=True):\n"
        "    orig(self, poll)\n"
        "    if self.frame_count >= 5 and self.state.scene is not None:\n"
        "        glfw.set_window_should_close(self.window, True)\n"
        "window.ViewerApp.step = step\n"
        "from gbviewer.cli import main\n"
        "sys.exit(main([]))\n"
    )
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp_path / "cfg"), PYTHONPATH=GBVIEWER_ROOT)
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=180
    )
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "cfg" / "gbviewer" / "settings.json").exists()
    assert not (tmp_path / "out").exists()  # the window opened: no fallback images


def test_cameras_from_the_command_line(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.window import ViewerApp

    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 60, 5, width=320, height=240)
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
    proc = subprocess.run(
        [sys.executable, "-m", "gbviewer", "--width", "64", "--height", "48"],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr
    assert "no display" in proc.stdout
    assert (tmp_path / "out" / "comparison.png").exists()
