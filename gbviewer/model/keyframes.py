"""Keyframed camera paths: cubic Hermite through the keys (Catmull-Rom for positions, monotone for log rate and
focal lengths), SQUAD (spherical cubic built from slerps, Shoemake 1987) for rotations; keys from and to JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.errors import CameraError, GBViewerError, InvalidValue
from ..core.validate import array, field, read_json, real
from .camera import UP_AXES, Camera, focal_from_fov, orbit_camera, parse_projection, parse_rate
from .cells import quats_from_matrices, rotation_matrices
from .scene import Scene

MAX_FOV_DEG = 179.0
POSES = {
    "R": ("R", "t"),
    "rotation": ("rotation", "position"),
    "look_at": ("position", "look_at", "up"),
    "orbit": ("orbit",),
}
INTRINSICS = ("fx", "fy", "cx", "cy")
FIELDS = frozenset(
    {f for fs in POSES.values() for f in fs} | set(INTRINSICS) | {"time", "rate", "fov_y_deg", "projection"}
)


@dataclass(frozen=True)
class Keyframe:
    """A key of a keyframed path: the camera (pose and intrinsics at the pane size), the sampling rate it is
    rendered at (then nearest-resized to the pane, as in the rate sweep), and its time in seconds (None: keys
    evenly spaced)."""

    camera: Camera
    rate: float = 1.0
    time: float | None = None


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of one rotation matrix, with w >= 0."""
    q = quats_from_matrices(np.asarray(R, np.float64)[None])[0]
    return q if q[0] >= 0 else -q


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z), normalised first."""
    q = np.asarray(q, np.float64)
    return rotation_matrices((q / np.linalg.norm(q))[None])[0]


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def _qconj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _qlog(q: np.ndarray) -> np.ndarray:
    """Log of a unit quaternion: (0, angle/2 * axis)."""
    v = q[1:]
    n = np.linalg.norm(v)
    if n < 1e-12:
        return np.zeros(4)
    return np.concatenate([[0.0], v / n * math.atan2(n, q[0])])


def _qexp(q: np.ndarray) -> np.ndarray:
    v = q[1:]
    n = np.linalg.norm(v)
    if n < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[math.cos(n)], v / n * math.sin(n)])


def slerp(a: np.ndarray, b: np.ndarray, h: float) -> np.ndarray:
    """Spherical linear interpolation from a (h = 0, returned exactly) to b (h = 1); no hemisphere flip."""
    d = float(np.clip(np.dot(a, b), -1.0, 1.0))
    theta = math.acos(d)
    if theta < 1e-9:
        return a * (1.0 - h) + b * h
    s = math.sin(theta)
    return a * (math.sin((1.0 - h) * theta) / s) + b * (math.sin(h * theta) / s)


def _squad_controls(qs: list[np.ndarray]) -> list[np.ndarray]:
    """Shoemake's inner control quaternions; the ends are their own keys (so two keys give a plain slerp)."""
    ctrl = [qs[0]]
    for k in range(1, len(qs) - 1):
        inv = _qconj(qs[k])
        ctrl.append(_qmul(qs[k], _qexp(-(_qlog(_qmul(inv, qs[k + 1])) + _qlog(_qmul(inv, qs[k - 1]))) / 4.0)))
    if len(qs) > 1:
        ctrl.append(qs[-1])
    return ctrl


def _catmull_rom_tangents(ts: np.ndarray, p: np.ndarray) -> np.ndarray:
    """dp/dt at the keys: central differences over non-uniform times, one-sided at the ends."""
    m = np.empty_like(p)
    if len(ts) == 1:
        return np.zeros_like(p)
    m[0] = (p[1] - p[0]) / (ts[1] - ts[0])
    m[-1] = (p[-1] - p[-2]) / (ts[-1] - ts[-2])
    for k in range(1, len(ts) - 1):
        m[k] = (p[k + 1] - p[k - 1]) / (ts[k + 1] - ts[k - 1])
    return m


def _monotone_tangents(ts: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson (PCHIP weights) tangents per column: no overshoot between keys."""
    m = np.zeros_like(y)
    if len(ts) == 1:
        return m
    h = np.diff(ts)[:, None]
    d = np.diff(y, axis=0) / h
    m[0], m[-1] = d[0], d[-1]
    for k in range(1, len(ts) - 1):
        w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
        same = d[k - 1] * d[k] > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            m[k] = np.where(same, (w1 + w2) / (w1 / d[k - 1] + w2 / d[k]), 0.0)
    return m


def _segment(ts: np.ndarray, t: float) -> tuple[int, float]:
    """Segment k with ts[k] <= t <= ts[k + 1] and the fraction h along it (h = 0 exactly at a key)."""
    k = int(np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2))
    return k, (t - ts[k]) / (ts[k + 1] - ts[k])


def _hermite(ts: np.ndarray, p: np.ndarray, m: np.ndarray, k: int, h: float) -> np.ndarray:
    dt = ts[k + 1] - ts[k]
    h2, h3 = h * h, h * h * h
    return (
        (2 * h3 - 3 * h2 + 1) * p[k]
        + (h3 - 2 * h2 + h) * dt * m[k]
        + (-2 * h3 + 3 * h2) * p[k + 1]
        + (h3 - h2) * dt * m[k + 1]
    )


def key_times(keys: Sequence[Keyframe]) -> np.ndarray:
    """The keys' times: as given (strictly increasing), or 0, 1, 2, ... when none has one."""
    given = [k.time for k in keys]
    if all(t is None for t in given):
        return np.arange(len(keys), dtype=np.float64)
    if any(t is None for t in given):
        raise GBViewerError("keyframes: give a time to every key or to none")
    ts = np.asarray(given, np.float64)
    if not np.isfinite(ts).all() or (len(ts) > 1 and not (np.diff(ts) > 0).all()):
        raise GBViewerError(f"keyframes: times must be finite and strictly increasing, got {given}")
    return ts


def interpolate_keyframes(keys: Sequence[Keyframe], times: Sequence[float]) -> list[Keyframe]:
    """The path through `keys` at `times` (clamped to the keys' span); at a key's time it is that key (up to
    rounding). Positions (camera centres): Catmull-Rom cubic; rotations: SQUAD; rate, fx, fy: monotone cubic in
    log; cx, cy: monotone cubic. Every key must have the same image size and projection."""
    if not keys:
        raise GBViewerError("keyframes: none given")
    first = keys[0].camera
    if any((k.camera.width, k.camera.height) != (first.width, first.height) for k in keys):
        raise GBViewerError("keyframes: every key's camera must have the same image size")
    if any(k.camera.projection != first.projection for k in keys):
        raise GBViewerError("keyframes: every key's camera must have the same projection")
    for k in keys:
        if not (k.rate > 0 and math.isfinite(k.rate)):
            raise GBViewerError(f"keyframes: rate must be finite and > 0, got {k.rate}")
    ts = key_times(keys)
    if len(keys) == 1:
        return [replace(keys[0], time=float(t)) for t in times]
    pos = np.stack([k.camera.position for k in keys])
    qs = [quat_from_matrix(k.camera.R) for k in keys]
    for i in range(1, len(qs)):  # shortest arcs
        if np.dot(qs[i - 1], qs[i]) < 0:
            qs[i] = -qs[i]
    ctrl = _squad_controls(qs)
    scal = np.stack(
        [[math.log(k.rate), math.log(k.camera.fx), math.log(k.camera.fy), k.camera.cx, k.camera.cy] for k in keys]
    )
    m_pos, m_scal = _catmull_rom_tangents(ts, pos), _monotone_tangents(ts, scal)
    out = []
    for t in times:
        t = float(np.clip(t, ts[0], ts[-1]))
        k, hh = _segment(ts, t)
        c = _hermite(ts, pos, m_pos, k, hh)
        q = slerp(slerp(qs[k], qs[k + 1], hh), slerp(ctrl[k], ctrl[k + 1], hh), 2 * hh * (1 - hh))
        lr, lfx, lfy, cx, cy = _hermite(ts, scal, m_scal, k, hh)
        R = matrix_from_quat(q)
        cam = replace(
            keys[0].camera, R=R, t=-R @ c, fx=math.exp(lfx), fy=math.exp(lfy), cx=cx, cy=cy, name=f"keyframes@{t:g}"
        )
        out.append(Keyframe(cam, math.exp(lr), t))
    return out


def load_keyframes(path: str | Path, base: Camera, scene: Scene | None = None, up: str = "-y") -> list[Keyframe]:
    """Keyframes from JSON: {"keyframes": [KEY, ...]} or a bare list of KEYs. A KEY gives a pose as one of

      {"R": 3x3, "t": [3]}                    world-to-camera, as gb.Camera (x_cam = R x + t; OpenCV axes)
      {"rotation": 3x3, "position": [3]}      camera-to-world rotation and centre, as a 3DGS cameras.json entry
      {"position": [3], "look_at": [3], "up": [3]}   eye, target and world up (default: the --up axis)
      {"orbit": [azimuth, elevation, distance]}      degrees, scene units (distance <= 0 or null: auto framing)

    and optionally "time" (seconds; give it to all keys or none), "rate" (sampling rate rendered at, default 1:
    rendered at that rate and shown nearest-upscaled), "fov_y_deg" or "fx", "fy", "cx", "cy" (pixels at the pane
    size; default: the base camera's intrinsics), "projection" (default: the base camera's; "orthographic": fx, fy
    are pixels per world unit, and a key that changes the base's projection gives them; no fov_y_deg). The pane size
    is the base camera's. Every value is checked: a bad one is a one-line `InvalidValue` naming the file, the key's
    index and the field, and so is an unknown field, a key with two poses (or a field of another pose), fov_y_deg
    with fx/fy/cx/cy, or keys of different projections.
    """
    path = Path(path)
    doc = read_json(path)
    entries = doc.get("keyframes") if isinstance(doc, dict) else doc
    if not isinstance(entries, list) or not entries:
        raise InvalidValue(f'{path}: expected a non-empty list of keyframes (or {{"keyframes": [...]}})')
    keys = []
    for i, e in enumerate(entries):
        where = f"{path}: keyframe {i}"
        try:
            keys.append(_keyframe(e, where, i, base, scene, up))
        except CameraError as exc:
            raise InvalidValue(f"{where}: {exc}") from None
    for i, k in enumerate(keys):
        if k.camera.projection != keys[0].camera.projection:
            raise InvalidValue(
                f"{path}: keyframe {i}: 'projection' {k.camera.projection} differs from keyframe 0's "
                f"({keys[0].camera.projection}); all keys share one projection"
            )
    try:
        key_times(keys)
    except GBViewerError as exc:
        raise InvalidValue(f"{path}: {exc}") from None
    return keys


def _keyframe(e: object, where: str, i: int, base: Camera, scene: Scene | None, up: str) -> Keyframe:
    """One key of a keyframes file (see `load_keyframes`)."""
    if not isinstance(e, dict):
        raise InvalidValue(f"{where}: expected a JSON object, got {type(e).__name__}")

    def vec(name: str, shape: tuple[int, ...]) -> np.ndarray:
        return array(field(e, name, where), f"{where}: '{name}'", shape, f32=True)

    def num(name: str, **bounds) -> float:
        return _number(e[name], f"{where}: '{name}'", **bounds)

    _check_fields(e, where)
    if "R" in e:
        R, t = vec("R", (3, 3)), vec("t", (3,))
    elif "rotation" in e:
        R = vec("rotation", (3, 3)).T
        t = -R @ vec("position", (3,))
    elif "look_at" in e:
        c = Camera.look_at(vec("position", (3,)), vec("look_at", (3,)), vec("up", (3,)) if "up" in e else UP_AXES[up])
        R, t = c.R, c.t
    elif "orbit" in e:
        if scene is None:
            raise InvalidValue(f"{where}: 'orbit' keys need the scene")
        orbit = e["orbit"]
        if not isinstance(orbit, list) or len(orbit) not in (2, 3):
            raise InvalidValue(
                f"{where}: 'orbit': expected [azimuth, elevation] or [azimuth, elevation, distance], "
                f"got {str(orbit):.40}"
            )
        az, el = (_number(v, f"{where}: 'orbit' {n}") for v, n in zip(orbit, ("azimuth", "elevation")))
        dist = _number(orbit[2], f"{where}: 'orbit' distance") if len(orbit) == 3 and orbit[2] is not None else 0.0
        c = orbit_camera(scene, az, el, dist if dist > 0 else None, base.width, base.height, up=up)
        R, t = c.R, c.t
    else:
        raise InvalidValue(f"{where}: no pose; give R and t, rotation and position, position and look_at, or orbit")
    intr = dict(fx=base.fx, fy=base.fy, cx=base.cx, cy=base.cy)
    projection = parse_projection(e.get("projection", base.projection), f"{where}: 'projection'")
    if projection != base.projection and not ("fx" in e and "fy" in e):
        raise InvalidValue(
            f"{where}: 'projection' {projection} differs from the camera's ({base.projection}); give 'fx' and 'fy' too"
        )
    if "fov_y_deg" in e and projection == "orthographic":
        raise InvalidValue(
            f"{where}: 'fov_y_deg' has no meaning for an orthographic camera; give 'fx' and 'fy' "
            f"(pixels per world unit)"
        )
    given = [k for k in INTRINSICS if k in e]
    if "fov_y_deg" in e and given:
        raise InvalidValue(f"{where}: 'fov_y_deg' and '{given[0]}' both set the intrinsics; give one or the other")
    if "fov_y_deg" in e:
        f = focal_from_fov(num("fov_y_deg", lo=0, lo_open=True, hi=MAX_FOV_DEG), base.height)
        intr = dict(fx=f, fy=f, cx=base.width / 2, cy=base.height / 2)
    intr.update(
        {
            k: num(k, **({"lo": 0, "lo_open": True} if k in ("fx", "fy") else {}))
            for k in ("fx", "fy", "cx", "cy")
            if k in e
        }
    )
    cam = replace(base, R=R, t=t, name=f"key{i}", projection=projection, **intr)
    rate = parse_rate(e.get("rate", 1), f"{where}: 'rate'")
    time_ = num("time") if e.get("time") is not None else None
    return Keyframe(cam, rate, time_)


def _check_fields(e: dict, where: str) -> None:
    """Refuse an unknown field, two poses in one key, or a pose's field given with another pose."""
    unknown = sorted(str(k) for k in e if k not in FIELDS)
    if unknown:
        raise InvalidValue(f"{where}: unknown field {unknown[0]!r:.40} (expected {', '.join(sorted(FIELDS))})")
    poses = [p for p in POSES if p in e]
    if len(poses) > 1:
        raise InvalidValue(f"{where}: '{poses[0]}' and '{poses[1]}' are two poses; give one")
    stray = [f for fs in POSES.values() for f in fs if f in e and (not poses or f not in POSES[poses[0]])]
    if poses and stray:
        raise InvalidValue(
            f"{where}: '{stray[0]}' does not belong to a '{poses[0]}' pose (that takes {', '.join(POSES[poses[0]])})"
        )


def _number(value: object, what: str, **bounds) -> float:
    """A JSON number (not a string of one: `real` would parse it) as a finite float32 in the bounds."""
    if isinstance(value, str):
        raise InvalidValue(f"{what}: expected a JSON number, got the string {value!r:.40}")
    return real(value, what, f32=True, **bounds)


def keyframes_to_json(keys: Sequence[Keyframe]) -> dict:
    """The JSON document `load_keyframes` reads back (world-to-camera R, t, the intrinsics and projection of every
    key)."""
    return {
        "keyframes": [
            {
                "R": k.camera.R.tolist(),
                "t": k.camera.t.tolist(),
                "fx": k.camera.fx,
                "fy": k.camera.fy,
                "cx": k.camera.cx,
                "cy": k.camera.cy,
                "projection": k.camera.projection,
                "rate": k.rate,
                **({"time": k.time} if k.time is not None else {}),
            }
            for k in keys
        ]
    }
