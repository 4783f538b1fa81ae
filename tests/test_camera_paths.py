"""Camera paths of zoom videos (gbviewer.camera_paths): zoom, dolly and rate sweeps scale the content as stated."""

from __future__ import annotations

import math

import numpy as np
import pytest

import gbviewer as gb
from gbviewer import camera_paths

W, H = 96, 64


@pytest.fixture(scope="module")
def scene() -> gb.Scene:
    return gb.load(gb.DEFAULT_SCENE)


@pytest.fixture(scope="module")
def base(scene) -> gb.Camera:
    return gb.orbit_camera(scene, 30, 20, width=W, height=H)


def test_zoom_and_dolly_scale_the_content(scene, base):
    z = camera_paths.zoom_path(base, 5, 1.0, 1.0 / 8.0)
    assert [pf.rate for pf in z] == pytest.approx([8 ** (-i / 4) for i in range(5)], rel=1e-12)
    assert z[0].camera.fx == base.fx and np.array_equal(z[0].camera.t, base.t)
    assert math.isclose(z[-1].camera.fx, base.fx / 8) and z[-1].camera.width == W
    depth = camera_paths.scene_focus_depth(scene, base)
    d = camera_paths.dolly_path(base, 3, 1.0, 1.0 / 4.0, depth)
    p_cam = np.array([0.3, -0.2, depth])  # a point at the focus depth, in base camera coordinates
    p_world = base.R.T @ (p_cam - base.t)
    for pf in d:
        q = pf.camera.R @ p_world + pf.camera.t
        u = pf.camera.fx * q[0] / q[2] + pf.camera.cx
        assert math.isclose(u - base.cx, pf.rate * base.fx * p_cam[0] / depth, rel_tol=1e-9)
    assert z[-1].map_box((base.cx - 8, base.cy, 16, 8)) == pytest.approx((base.cx - 1, base.cy, 2, 1))
    r = camera_paths.rate_path(base, 2, 1.0, 0.25)
    assert (r[-1].camera.width, r[-1].camera.height, r[-1].width) == (24, 16, W)

