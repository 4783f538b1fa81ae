"""Scene loading in the background, with a cameras.json beside the scene."""

from __future__ import annotations

import json
import math
import time

import pytest

import gbviewer as gb
from gbviewer.app.loading import SceneLoader


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
