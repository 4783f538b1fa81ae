"""The viewer's camera: one orbit / fly controller shared by every pane."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ...model.camera import NEAR_PLANE, UP_AXES, Camera, focal_from_fov, fov_of, frame_box, orbit_direction


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return c * np.eye(3) + s * K + (1 - c) * np.outer(axis, axis)


@dataclass(eq=False)
class CameraController:
    """One camera shared by every pane: a world-to-camera rotation R (OpenCV axes, rows x right, y down, z forward),
    an orbit target and the distance to it (the eye is target - distance * forward), a vertical field of view and
    the scene's up axis. Orbit and mouse look turn about the world up axis and the camera's x axis. The projection
    is perspective or orthographic (see `camera`)."""

    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance: float = 3.0
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    fov_y_deg: float = 50.0
    up: str = "-y"
    radius: float = 1.0  # scene size: sets pan, fly and dolly limits
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orbit_speed: float = 0.3  # degrees per pixel
    projection: str = "perspective"

    MIN_FOV, MAX_FOV = 5.0, 120.0

    @property
    def up_vector(self) -> np.ndarray:
        return np.array(UP_AXES[self.up], np.float64)

    @property
    def forward(self) -> np.ndarray:
        return self.R[2].copy()

    @property
    def eye(self) -> np.ndarray:
        return self.target - self.distance * self.R[2]

    def camera(self, width: int, height: int) -> Camera:
        """A centred camera of width x height pixels with this pose and vertical field of view. Orthographic: f /
        distance pixels per unit (f: the field of view's focal length), so the plane through the target keeps its
        size when the projection changes and the wheel's dolly zooms; seen from far enough back along the view that
        the scene's bounding sphere lies in front of the near plane, so zooming in never clips the scene."""
        f = focal_from_fov(self.fov_y_deg, height)
        cam = Camera(width, height, f, f, width / 2, height / 2, self.R, -self.R @ self.eye)
        if self.projection == "perspective":
            return cam
        back = max(self.distance, float(np.linalg.norm(self.target - self.centre)) + self.radius + 2 * NEAR_PLANE)
        cam = replace(cam, t=-self.R @ (self.target - back * self.R[2]))
        return cam.with_projection(self.projection, self.distance)

    def frame_bounds(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        azimuth_deg: float = 30.0,
        elevation_deg: float = 20.0,
        aspect: float = 4 / 3,
    ) -> None:
        """Default framing of the box lo..hi (as gbviewer.orbit_camera): orbit around its centre, far enough to see
        all of it."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.centre, self.radius, self.distance = frame_box(lo, hi, self.fov_y_deg, aspect)
        self.target = self.centre.copy()
        self._look(
            self.target + self.distance * orbit_direction(self.up_vector, azimuth_deg, elevation_deg), self.target
        )

    def _look(self, eye: np.ndarray, target: np.ndarray) -> None:
        cam = Camera.look_at(eye, target, self.up_vector, 64, 64, self.fov_y_deg)
        self.R = cam.R.copy()
        self.target = np.asarray(target, np.float64).copy()
        self.distance = float(np.linalg.norm(np.asarray(target) - np.asarray(eye)))

    def _turn(self, about_eye: bool, yaw: float, pitch: float) -> None:
        """Rotate the camera about the world up axis (yaw) and its own x axis (pitch), through the target (orbit)
        or the eye (look); pitch stops short of the poles and never turns the view upside down."""
        up = self.up_vector
        eye = self.eye
        rot = _rotation(up, yaw)
        R = self.R @ rot.T
        if pitch:
            rp = _rotation(R[0], pitch)
            R2 = R @ rp.T
            upright = float(self.R[1] @ -up) >= 0
            if abs(float(R2[2] @ up)) < 0.995 and (float(R2[1] @ -up) > 0) == upright:
                R = R2
        self.R = R
        if about_eye:
            self.target = eye + self.distance * R[2]

    def orbit(self, dx: float, dy: float) -> None:
        """Left drag: turn around the target by dx, dy pixels (drag right: the scene turns right)."""
        k = math.radians(self.orbit_speed)
        self._turn(False, -dx * k * self._up_sign(), -dy * k)

    def look(self, dx: float, dy: float) -> None:
        """Fly-mode mouse look: turn in place (drag right: look right)."""
        k = math.radians(self.orbit_speed) * 0.5
        self._turn(True, -dx * k * self._up_sign(), -dy * k)

    def _up_sign(self) -> float:
        # yaw about the world up axis turns the view right for positive angles when camera -y is along up
        return 1.0 if float(self.R[1] @ -self.up_vector) >= 0 else -1.0

    def pan(self, dx: float, dy: float, viewport_h: int) -> None:
        """Right/middle drag: the point under the cursor follows it (at the target's depth)."""
        scale = 2 * self.distance * math.tan(math.radians(self.fov_y_deg) / 2) / max(1, viewport_h)
        self.target = self.target - (dx * self.R[0] + dy * self.R[1]) * scale

    def dolly(self, steps: float) -> None:
        """Wheel: move towards (steps > 0) or away from the target, 10% of the distance per step."""
        self.distance = float(min(max(self.distance * 0.9**steps, 1e-3 * self.radius), 1e3 * self.radius))

    def fly(self, forward: float, right: float, upward: float, dt: float, speed: float = 1.0) -> None:
        """WASD/QE: move eye and target together, `speed` scene radii per second (upward is along the scene up)."""
        step = self.radius * speed * dt
        move = forward * self.R[2] + right * self.R[0] + upward * self.up_vector
        self.target = self.target + step * move

    def set_fov(self, fov_y_deg: float) -> None:
        self.fov_y_deg = float(min(self.MAX_FOV, max(self.MIN_FOV, fov_y_deg)))

    def set_up(self, up: str) -> None:
        """Change the scene's up axis and level the view to it (same eye and target)."""
        if up not in UP_AXES:
            raise ValueError(f"up axis {up!r}; expected one of {sorted(UP_AXES)}")
        eye, target = self.eye, self.target
        self.up = up
        self._look(eye, target)

    def snap_to(self, camera: Camera) -> None:
        """Take a (training) camera's pose and vertical field of view (an orthographic camera's: the one that gives
        its pixels per unit at the target); the target stays `distance` ahead. The projection stays."""
        self.R = camera.R.copy()
        dist = float(np.linalg.norm(self.centre - camera.position))
        self.distance = dist if dist > 1e-6 else self.distance
        self.fov_y_deg = float(
            min(self.MAX_FOV, max(self.MIN_FOV, fov_of(camera.with_projection("perspective", self.distance))))
        )
        self.target = camera.position + self.distance * self.R[2]

    def state(self) -> tuple:
        """A hashable summary (changes whenever the rendered view would)."""
        return (
            tuple(np.round(self.R.ravel(), 12)),
            tuple(np.round(self.target, 12)),
            round(self.distance, 12),
            round(self.fov_y_deg, 9),
            self.projection,
        )
