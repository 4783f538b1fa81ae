"""The orbit / fly camera controller."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.camera.control import CameraController
from gbviewer.model.camera import UP_AXES, fov_of


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
    up_v = np.array(UP_AXES[up])
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
    assert fov_of(cam) == pytest.approx(60)


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


def project_any(cam: gb.Camera, p) -> np.ndarray:
    x = cam.R @ np.asarray(p, float) + cam.t
    z = 1.0 if cam.orthographic else x[2]
    return np.array([cam.fx * x[0] / z + cam.cx, cam.fy * x[1] / z + cam.cy])


def test_orthographic_view_keeps_the_target_plane_and_zooms_with_the_wheel():
    """Switching the projection keeps the plane through the target at its size on screen; the wheel scales the
    pixels per unit; the whole scene stays in front of the near plane however far it zooms in; pan still moves the
    point under the cursor with it."""
    c = framed()
    persp = c.camera(640, 480)
    on_plane = c.target + 0.4 * c.R[0] - 0.3 * c.R[1]
    c.projection = "orthographic"
    ortho = c.camera(640, 480)
    assert ortho.orthographic and ortho.fy == pytest.approx(persp.fy / c.distance)
    assert project_any(ortho, on_plane) == pytest.approx(project_any(persp, on_plane), abs=1e-9)
    assert c.state() != replace(c, projection="perspective").state()
    fx0 = ortho.fx
    for _ in range(40):
        c.dolly(1)
    zoomed = c.camera(640, 480)
    assert zoomed.fx == pytest.approx(fx0 / 0.9**40)
    depth = (zoomed.R @ c.centre + zoomed.t)[2]
    assert depth - c.radius > zoomed.near, "part of the scene's sphere is behind the near plane"
    assert project_any(zoomed, c.target) == pytest.approx([320, 240], abs=1e-6)
    point = c.target.copy()
    c.pan(50, -20, 480)
    assert project_any(c.camera(640, 480), point) - [320, 240] == pytest.approx([50, -20], abs=1e-6)


def test_snap_to_an_orthographic_camera_keeps_its_scale():
    c = framed()
    c.projection = "orthographic"
    train = gb.Camera.look_at([2.0, -1, -3], [0.1, 0, 0], (0, -1, 0), 800, 600, 40.0).with_projection(
        "orthographic", 3.0
    )
    c.snap_to(train)
    cam = c.camera(800, 600)
    assert cam.orthographic and cam.R == pytest.approx(train.R) and cam.fy == pytest.approx(train.fy)
    assert project_any(cam, c.target) == pytest.approx(project_any(train, c.target), abs=1e-6)
