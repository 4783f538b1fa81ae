"""Scene loading in the background, with a cameras.json beside the scene; its progress (the viewer's determinate
bar) and cancelling it (Esc in the viewer keeps the current scene)."""

from __future__ import annotations

import json
import math
import shutil
import threading
import time

import plyfile
import pytest

import gbviewer as gb
from gbviewer.app.threads.loading import SceneLoader


def gated_load(gate: threading.Event):
    """gb.load, held at its first report past 0 until `gate` is set (a load that is surely half done)."""
    real = gb.io.load

    def load(path, progress=None, cancel=None):
        def report(done, total, unit):
            progress(done, total, unit)
            if done > 0:
                gate.wait(60)

        return real(path, progress=report, cancel=cancel)

    return load


def wait_for(predicate, timeout: float = 60.0, step=lambda: time.sleep(0.01)) -> None:
    t0 = time.time()
    while not predicate() and time.time() - t0 < timeout:
        step()
    assert predicate(), "timed out"


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
    (tmp_path / "cameras.json").write_text(
        json.dumps(
            [
                {
                    "id": 0,
                    "img_name": "v0",
                    "width": 64,
                    "height": 48,
                    "fx": cam.fx,
                    "fy": cam.fy,
                    "position": cam.position.tolist(),
                    "rotation": c2w.tolist(),
                }
            ]
        )
    )
    ld = SceneLoader(scene)
    while not ld.done():
        time.sleep(0.01)
    res = ld.poll()
    assert res.cameras_path == tmp_path / "cameras.json" and len(res.cameras) == 1
    assert res.cameras[0].R == pytest.approx(cam.R) and math.isclose(res.cameras[0].fx, cam.fx)


def test_scene_loader_reports_each_phase_to_its_end(tmp_path):
    ld = SceneLoader(gb.DEFAULT_SCENE)  # a binary INRIA .ply: read, scattered and activated in one phase
    wait_for(ld.done)
    size = gb.DEFAULT_SCENE.stat().st_size
    assert ld.progress == (size, size, "bytes") and ld.fraction == 1.0
    assert ld.describe() == f"reading 100% ({size / 1e6:.1f} / {size / 1e6:.1f} MB)"
    text = tmp_path / "text.ply"  # an ASCII one: read, then decoded
    plyfile.PlyData([plyfile.PlyData.read(str(gb.DEFAULT_SCENE))["vertex"]], text=True).write(str(text))
    ld = SceneLoader(text)
    wait_for(ld.done)
    n = ld.poll().scene.num_splats
    assert ld.progress == (n, n, "splats") and ld.fraction == 1.0
    assert ld.describe() == f"decoding 100% ({n:,} / {n:,} splats)"


def test_scene_loader_progress_is_determinate_and_cancel_stops_it():
    gate = threading.Event()
    ld = SceneLoader(gb.DEFAULT_SCENE, gated_load(gate))
    try:
        wait_for(lambda: ld.progress is not None and ld.progress[0] > 0)
        size = gb.DEFAULT_SCENE.stat().st_size
        assert ld.progress[1:] == (size, "bytes") and 0 < ld.fraction < 1
        assert (
            ld.describe().startswith(f"reading {100 * ld.fraction:.0f}% (")
            and f"/ {size / 1e6:.1f} MB" in ld.describe()
        )
        ld.cancel()
    finally:
        gate.set()
    wait_for(ld.done)
    res = ld.poll()
    assert res.cancelled and res.scene is None and res.error == ""


@pytest.mark.display
def test_viewer_bar_is_determinate_and_esc_cancels_keeping_the_scene(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.ui.keys import KEYS
    from gbviewer.app.window import ViewerApp

    gate = threading.Event()
    app = ViewerApp(None, size=(900, 600))
    try:
        assert app.wait_rendered(180)
        scene, path = app.state.scene, app.state.scene_path
        monkeypatch.setattr(gb.io, "load", gated_load(gate))
        other = tmp_path / "other.ply"
        shutil.copy(gb.DEFAULT_SCENE, other)
        app.state.open(other)
        loader = app.state.loader
        wait_for(lambda: loader.progress is not None and loader.progress[0] > 0, step=app.step)
        app.run_frames(3)  # the panel's bar and the banner drawn from it
        assert 0 < loader.fraction < 1 and loader.describe().startswith("reading")
        esc = next(k for k in KEYS if k.key == "escape")
        app.action(esc.action)(*esc.args)
        assert app.state.loader is None and app.state.scene is scene and app.state.scene_path == path
        assert "cancelled loading other.ply: kept the current scene" in app.state.messages[-1][1]
        gate.set()
        wait_for(loader.done)
        assert loader.poll().cancelled  # the load thread stopped within a chunk of the release
        assert app.wait_rendered(180) and app.state.scene is scene and app.state.load_error == ""
    finally:
        gate.set()
        app.close()
