"""Cameras (OpenCV axes: x right, y down, z forward), perspective or orthographic, and where they come from."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import CameraError, InvalidValue
from ..core.validate import F32_MAX, array, distinct_items, field, integer, read_json, real

if TYPE_CHECKING:
    from .scene import Scene

NEAR_PLANE = 0.2  # published 3DGS near cull (docs/modes.md#culling-radius-tiles)
MIN_RATE, MAX_RATE = 1e-3, 64.0  # sampling rates: x1/1000 (zoomed out) to x64 (supersampled)
MAX_IMAGE_SIZE = 16384  # pixels per axis of any camera
ROTATION_TOLERANCE = 1e-3  # |R R^T - I| and |det R - 1| allowed for a rotation read from a file
UP_AXES = {"-y": (0.0, -1.0, 0.0), "+y": (0.0, 1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
PROJECTIONS = ("perspective", "orthographic")  # the index is the native modules' and shaders' projection code


def format_rate(rate: float) -> str:
    """x8, x1, x1/8 style label for a sampling rate; rates between simple fractions (a continuous zoom) read
    x1/3.7 or x2.5."""
    f = Fraction(rate).limit_denominator(64)
    if abs(float(f) - rate) <= 1e-9 * rate and 1 in (f.numerator, f.denominator):
        return f"x{f.numerator}" if f.denominator == 1 else f"x{f.numerator}/{f.denominator}"
    return f"x1/{1 / rate:.3g}" if rate < 1 else f"x{rate:.3g}"


def parse_rate(text: object, what: str | None = None) -> float:
    """'1/8', '0.125' or '8' (or a number) -> a float in [MIN_RATE, MAX_RATE]; `InvalidValue` naming `what` (by
    default the text) otherwise."""
    what = what or f"sampling rate {str(text).strip()!r:.40}"
    num, slash, den = str(text).partition("/")
    value = real(num, what) / real(den, what, lo=0.0, lo_open=True) if slash else real(num, what)
    return real(value, what, lo=MIN_RATE, hi=MAX_RATE)


def parse_projection(value: object, what: str) -> str:
    """'perspective' or 'orthographic'; `InvalidValue` naming `what` otherwise."""
    if value not in PROJECTIONS:
        raise InvalidValue(f"{what}: expected perspective or orthographic, got {str(value)!r:.40}")
    return str(value)


def parse_rates(text: str) -> list[float]:
    """Comma-separated sampling rates ('1,1/2,1/8'); at least one, each once (1/2 and 0.5 are the same), none
    empty."""
    return distinct_items(text, "rates", parse_rate)


def focal_from_fov(fov_y_deg: float, height: float) -> float:
    """Focal length in pixels that spans `fov_y_deg` degrees over `height` pixels."""
    return 0.5 * height / math.tan(math.radians(fov_y_deg) / 2)


def fov_of(camera: "Camera") -> float:
    """Vertical field of view of a camera, degrees."""
    return math.degrees(2 * math.atan(camera.height / (2 * camera.fy)))


def frame_box(lo: np.ndarray, hi: np.ndarray, fov_y_deg: float, aspect: float) -> tuple[np.ndarray, float, float]:
    """Centre and radius of the box lo..hi, and the distance from its centre at which a camera with this vertical
    field of view and aspect (width / height) sees all of it (the default orbit framing)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)  # float32 bounds near 1e38 overflow in float32
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    fov = math.radians(fov_y_deg) * min(1.0, aspect)
    return centre, radius, radius / math.sin(fov / 2) * 0.9


def orbit_direction(up: np.ndarray, azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector from an orbit's centre to its eye: azimuth about the `up` vector, elevation towards it."""
    a = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0])  # (a, b): the azimuth plane
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return math.cos(el) * (math.cos(az) * a + math.sin(az) * b) + math.sin(el) * up


@dataclass(frozen=True)
class Camera:
    """Intrinsics in pixels and a world-to-camera pose: x_cam = R @ x_world + t.

    Pixel (i, j) covers [j, j+1] x [i, i+1]; a centred 3DGS camera has cx = W/2, cy = H/2. A perspective (pinhole)
    camera puts x_cam = (X, Y, Z) at (fx X/Z + cx, fy Y/Z + cy), fx and fy in pixels; an orthographic one at
    (fx X + cx, fy Y + cy), fx and fy in pixels per world unit, and sees every point along its forward axis (parallel
    rays: the SH view direction of every splat). Both see only what lies more than `near` in front of the plane
    z = 0 through `position`, and sort by Z.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    R: np.ndarray
    t: np.ndarray
    near: float = NEAR_PLANE
    name: str = ""
    projection: str = "perspective"

    def __post_init__(self) -> None:
        """Every number checked (the renderers take them as float32 and int32): sizes 1..MAX_IMAGE_SIZE, focal
        lengths and near plane finite and > 0, a rotation R and a float32 translation t; projection one of
        PROJECTIONS."""
        who = f"camera {self.name!r:.60}"
        try:
            parse_projection(self.projection, f"{who}: projection")
            checked = {
                "width": integer(self.width, f"{who}: width", lo=1, hi=MAX_IMAGE_SIZE),
                "height": integer(self.height, f"{who}: height", lo=1, hi=MAX_IMAGE_SIZE),
                "R": array(self.R, f"{who}: R", (3, 3), f32=True),
                "t": array(self.t, f"{who}: t", (3,), f32=True),
            }
            for name in ("fx", "fy", "near"):
                checked[name] = real(getattr(self, name), f"{who}: {name}", lo=0, lo_open=True, f32=True)
            for name in ("cx", "cy"):
                checked[name] = real(getattr(self, name), f"{who}: {name}", f32=True)
        except InvalidValue as exc:
            raise CameraError(str(exc)) from None
        for name in ("R", "t"):  # a read-only copy: a camera compares and hashes by value, and the caller's array
            checked[name] = np.array(checked[name])  # edited after would have moved it unchecked
            checked[name].flags.writeable = False
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        R = checked["R"]
        if abs(np.linalg.det(R) - 1) > ROTATION_TOLERANCE or np.abs(R @ R.T - np.eye(3)).max() > ROTATION_TOLERANCE:
            raise CameraError(f"{who}: R is not a rotation matrix (det {np.linalg.det(R):.4g})")

    def __eq__(self, other: object) -> bool:
        """Equal when every field is: the arrays by value (a dataclass's own comparison of array fields raises on
        Python 3.13, which compares field by field)."""
        if not isinstance(other, Camera):
            return NotImplemented
        return camera_key(self) == camera_key(other) and self.name == other.name

    def __hash__(self) -> int:
        return hash((camera_key(self), self.name))

    @property
    def position(self) -> np.ndarray:
        """Camera centre in world coordinates (orthographic: the centre of its plane z = 0)."""
        return -self.R.T @ self.t

    @property
    def orthographic(self) -> bool:
        return self.projection == "orthographic"

    @property
    def projection_code(self) -> int:
        """The projection as the native modules and shaders take it (gbv::Projection)."""
        return PROJECTIONS.index(self.projection)

    def view_rays(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions (N, 3) along which the camera sees the world points (N, 3), and the distances (N,) along
        them: from the eye (perspective), or along the forward axis from the plane z = 0 (orthographic: parallel
        rays, the distance is the depth Z)."""
        points = np.asarray(points, np.float64)
        if self.orthographic:
            forward = self.R[2] / np.linalg.norm(self.R[2])
            return np.tile(forward, (len(points), 1)), points @ self.R[2] + self.t[2]
        d = points - self.position
        dist = np.linalg.norm(d, axis=1)
        return d / np.maximum(dist, 1e-30)[:, None], dist

    def with_projection(self, projection: str, depth: float) -> "Camera":
        """The same pose and image with `projection`, scaled so that things at camera depth `depth` keep their size
        on screen: a focal length of f pixels becomes f / depth pixels per unit, and back."""
        if projection == self.projection:
            return self
        try:
            k = real(depth, "depth at which the projections agree", lo=0, lo_open=True)
        except InvalidValue as exc:
            raise CameraError(str(exc)) from None
        k = 1 / k if projection == "orthographic" else k
        return replace(self, fx=self.fx * k, fy=self.fy * k, projection=projection)

    def at_sampling_rate(self, s: float) -> "Camera":
        """The same view with s times as many pixels per axis (s = 1/8 zooms out 8x, s = 8 zooms in)."""
        try:
            s = real(s, "sampling rate", lo=0, lo_open=True, hi=MAX_IMAGE_SIZE)
        except InvalidValue as exc:
            raise CameraError(str(exc)) from None
        w, h = max(1, round(self.width * s)), max(1, round(self.height * s))
        sx, sy = w / self.width, h / self.height
        try:
            return replace(self, width=w, height=h, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy)
        except CameraError as exc:
            raise CameraError(f"{exc} at sampling rate {format_rate(s)}") from None

    def with_size(self, width: int, height: int) -> "Camera":
        """Same pose and field of view at another resolution."""
        return replace(
            self,
            width=width,
            height=height,
            fx=self.fx * width / self.width,
            fy=self.fy * height / self.height,
            cx=self.cx * width / self.width,
            cy=self.cy * height / self.height,
        )

    @staticmethod
    def look_at(
        eye: np.ndarray,
        target: np.ndarray,
        up: np.ndarray | tuple[float, float, float] = UP_AXES["-y"],
        width: int = 640,
        height: int = 480,
        fov_y_deg: float = 50.0,
        name: str = "",
    ) -> "Camera":
        """A centred pinhole camera at `eye` looking at `target`, with `up` pointing up on screen."""
        eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
        z = target - eye
        if np.linalg.norm(z) < 1e-12:
            raise CameraError("look_at: eye and target coincide")
        z /= np.linalg.norm(z)
        up_v = np.asarray(up, np.float64)
        x = np.cross(-up_v, z)  # image y points down: camera +y is -up, and x = y cross z
        if np.linalg.norm(x) < 1e-6:
            x = np.cross(np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 0.0, 1.0]), z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])  # rows: camera axes in world
        f = focal_from_fov(fov_y_deg, height)
        return Camera(width, height, f, f, width / 2, height / 2, R, -R @ eye, name=name)


def orbit_camera(
    scene: "Scene",
    azimuth_deg: float = 30.0,
    elevation_deg: float = 20.0,
    distance: float | None = None,
    width: int = 640,
    height: int = 480,
    fov_y_deg: float = 50.0,
    up: str = "-y",
    projection: str = "perspective",
) -> Camera:
    """A camera orbiting the scene's robust centre; default distance frames the robust bounds.

    Percentile bounds keep stray far splats from pushing the camera away. An orthographic orbit stands at the same
    eye with f / distance pixels per unit (f: the perspective focal length of `fov_y_deg`), so the plane through
    the orbit centre, and with it the scene, fills the view as in the perspective orbit.
    """
    if up not in UP_AXES:
        raise CameraError(f"up axis {up!r}; expected one of {sorted(UP_AXES)}")
    try:  # checked before the framing divides by them
        width, height = (
            integer(v, f"orbit {name}", lo=1, hi=MAX_IMAGE_SIZE) for v, name in ((width, "width"), (height, "height"))
        )
        fov_y_deg = real(fov_y_deg, "orbit field of view (degrees)", lo=0, hi=180, lo_open=True)
        azimuth_deg, elevation_deg = (
            real(v, f"orbit {name} (degrees)") for v, name in ((azimuth_deg, "azimuth"), (elevation_deg, "elevation"))
        )
        if distance is not None:
            distance = real(distance, "orbit distance", lo=0, lo_open=True, f32=True)
    except InvalidValue as exc:
        raise CameraError(str(exc)) from None
    centre, radius, framing = frame_box(*scene.robust_bounds(), fov_y_deg, width / height)
    up_v = np.array(UP_AXES[up])
    distance = framing if distance is None else distance
    eye = centre + distance * orbit_direction(up_v, azimuth_deg, elevation_deg)
    if np.abs(eye).max() > F32_MAX:
        raise CameraError(
            f"{scene.source}: an orbit camera around this scene ({2 * radius:.3g} across) would sit at "
            f"{np.abs(eye).max():.3g}, beyond float32; give a camera"
        )
    cam = Camera.look_at(eye, centre, up_v, width, height, fov_y_deg, name=f"orbit({azimuth_deg},{elevation_deg})")
    return cam.with_projection(projection, distance)


def load_cameras_json(path: str | Path) -> list[Camera]:
    """Cameras from a 3DGS `cameras.json` (camera-to-world rotation rows and centre; fx, fy at full size), and
    gbviewer's optional "projection" per entry ("orthographic": fx, fy in pixels per world unit). Every field is
    checked: a bad one is a one-line `CameraError` naming the file, the entry and the key."""
    path = Path(path)
    try:
        entries = read_json(path)
        if not isinstance(entries, list) or not entries:
            raise InvalidValue(f"{path}: expected a non-empty JSON list of cameras")
        return [_camera_entry(e, f"{path}: entry {k}", k) for k, e in enumerate(entries)]
    except InvalidValue as exc:
        raise CameraError(str(exc)) from None


def _camera_entry(e: object, where: str, k: int) -> Camera:
    """One cameras.json entry: width, height, fx, fy, rotation (3x3), position (3), optional img_name or id and
    projection."""
    w, h = (integer(field(e, key, where), f"{where}: '{key}'", lo=1, hi=MAX_IMAGE_SIZE) for key in ("width", "height"))
    fx, fy = (real(field(e, key, where), f"{where}: '{key}'", lo=0, lo_open=True, f32=True) for key in ("fx", "fy"))
    R = array(field(e, "rotation", where), f"{where}: 'rotation'", (3, 3), f32=True).T  # stored camera-to-world
    pos = array(field(e, "position", where), f"{where}: 'position'", (3,), f32=True)
    name = str(e.get("img_name", e.get("id", k)))  # type: ignore[union-attr]  (field() proved e a dict)
    projection = parse_projection(
        e.get("projection", "perspective"),  # type: ignore[union-attr]
        f"{where}: 'projection'",
    )
    try:
        return Camera(w, h, fx, fy, w / 2, h / 2, R, -R @ pos, name=name, projection=projection)
    except CameraError as exc:
        raise InvalidValue(f"{where}: {exc}") from None


def camera_key(camera: Camera) -> tuple:
    """A hashable key equal for cameras that render the same pixels (size, intrinsics, pose, near plane,
    projection)."""
    return (
        camera.width,
        camera.height,
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        np.asarray(camera.R, np.float32).tobytes(),
        np.asarray(camera.t, np.float32).tobytes(),
        camera.near,
        camera.projection,
    )
