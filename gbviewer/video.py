"""Zoom videos and comparison figures.

Camera paths (`zoom_path`, `dolly_path`, `rate_path`, keyframes from JSON with `keyframe_path`), a side-by-side
H.264 MP4 of several modes streamed frame by frame to imageio-ffmpeg's bundled ffmpeg (`record_video`), and the
modes x rates comparison grid with PSNR under each cell (`compare_figure`).

Sampling rate s: the content is sampled s times as densely per axis as in the x1 view (s = 1/8: zoomed out 8x).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from PIL import Image

from .camera import UP_AXES, Camera, orbit_camera
from .errors import CameraError, GBViewerError
from .figure import Cell, GridLayout, compose_grid, format_rate, render_grid, save_image
from .io.files import atomic_write
from .render import Mode, RenderSettings, get_renderer
from .scene import Scene

PATHS = ("zoom", "dolly", "rate")
DEFAULT_CRF = 18  # libx264 constant rate factor: 0 lossless, ~18 visually lossless, 23 ffmpeg's default
GAP = 4  # pixels between panes


class Cancelled(GBViewerError):
    """`record_video` stopped because its cancel event was set; no output (and no temporary file) is left."""


# --------------------------------------------------------------------------------------------------------------
# camera paths


@dataclass(frozen=True)
class PathFrame:
    """One frame of a camera path.

    camera: what is rendered (for rate sweeps smaller or larger than the pane; the render is then resized to the
    pane with nearest filtering). rate: the sampling rate written on the frame. width, height: the pane (output)
    size. content_scale, centre: the apparent size of the content relative to x1, about the pane point `centre`;
    it carries an inset region given in x1 pixels to where that content is on this frame (`map_box`).
    """

    camera: Camera
    rate: float
    width: int
    height: int
    content_scale: float = 1.0
    centre: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def of(cls, camera: Camera) -> "PathFrame":
        """A camera rendered as is, at rate 1."""
        return cls(camera, 1.0, camera.width, camera.height, 1.0, (camera.cx, camera.cy))

    def map_box(self, box: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        """(x, y, w, h) in x1 pixels -> pane pixels on this frame."""
        s, (cx, cy) = self.content_scale, self.centre
        x, y, w, h = box
        return cx + (x - cx) * s, cy + (y - cy) * s, w * s, h * s


def geometric_rates(start: float, end: float, frames: int) -> list[float]:
    """`frames` rates from `start` to `end` (both included), evenly spaced in log: a steady zoom."""
    if not (start > 0 and end > 0 and math.isfinite(start) and math.isfinite(end)):
        raise GBViewerError(f"rates must be finite and > 0, got {start} and {end}")
    if frames < 1:
        raise GBViewerError(f"a video needs at least one frame, got {frames}")
    if frames == 1:
        return [start]
    return [start * (end / start) ** (i / (frames - 1)) for i in range(frames - 1)] + [end]


def zoom_path(base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0) -> list[PathFrame]:
    """The focal length goes from start x to end x the base camera's, geometrically; the pane size stays.

    At rate s the content appears s times its x1 size (about the principal point), so it is sampled at rate s."""
    return [PathFrame(replace(base, fx=base.fx * s, fy=base.fy * s), s, base.width, base.height, s,
                      (base.cx, base.cy)) for s in geometric_rates(start, end, frames)]


def dolly_path(base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0,
               focus_depth: float = 1.0) -> list[PathFrame]:
    """The camera moves along its optical axis so that things at `focus_depth` (camera z of the base camera)
    appear s times their x1 size: it stands at depth focus_depth / s from them. Nearer and farther things scale
    differently (that is what distinguishes a dolly from a zoom)."""
    if not (focus_depth > 0 and math.isfinite(focus_depth)):
        raise GBViewerError(f"dolly: focus depth must be > 0, got {focus_depth}")
    out = []
    for s in geometric_rates(start, end, frames):
        t = base.t + np.array([0.0, 0.0, focus_depth * (1.0 / s - 1.0)])
        out.append(PathFrame(replace(base, t=t), s, base.width, base.height, s, (base.cx, base.cy)))
    return out


def rate_path(base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0) -> list[PathFrame]:
    """The view stays; frame i is rendered at sampling rate s_i (`Camera.at_sampling_rate`, so the image size
    changes in whole-pixel steps) and shown resized to the pane with nearest filtering."""
    return [PathFrame(base.at_sampling_rate(s), s, base.width, base.height, 1.0, (base.cx, base.cy))
            for s in geometric_rates(start, end, frames)]


def scene_focus_depth(scene: Scene, camera: Camera) -> float:
    """Camera depth of the centre of the scene's robust bounds (the dolly's focus)."""
    lo, hi = scene.robust_bounds()
    z = float((camera.R @ ((np.asarray(lo, np.float64) + hi) / 2) + camera.t)[2])
    if not z > camera.near:
        raise GBViewerError(f"dolly: the scene's centre is not in front of the camera (depth {z:.3g}); use --path zoom")
    return z


# --------------------------------------------------------------------------------------------------------------
# keyframes: cubic Hermite through the keys (Catmull-Rom for positions, monotone for log rate and focal lengths),
# SQUAD (spherical cubic built from slerps, Shoemake 1987) for rotations


@dataclass(frozen=True)
class Keyframe:
    """A key of a keyframed path: the camera (pose and intrinsics at the pane size), the sampling rate it is
    rendered at (then nearest-resized to the pane, as in the rate sweep), and its time in seconds (None: keys
    evenly spaced)."""

    camera: Camera
    rate: float = 1.0
    time: float | None = None


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method; w >= 0)."""
    R = np.asarray(R, np.float64)
    tr = np.trace(R)
    if tr > 0:
        S = math.sqrt(tr + 1.0) * 2
        q = [0.25 * S, (R[2, 1] - R[1, 2]) / S, (R[0, 2] - R[2, 0]) / S, (R[1, 0] - R[0, 1]) / S]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        S = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [(R[2, 1] - R[1, 2]) / S, 0.25 * S, (R[0, 1] + R[1, 0]) / S, (R[0, 2] + R[2, 0]) / S]
    elif R[1, 1] > R[2, 2]:
        S = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 2] - R[2, 0]) / S, (R[0, 1] + R[1, 0]) / S, 0.25 * S, (R[1, 2] + R[2, 1]) / S]
    else:
        S = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[1, 0] - R[0, 1]) / S, (R[0, 2] + R[2, 0]) / S, (R[1, 2] + R[2, 1]) / S, 0.25 * S]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


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
    return ((2 * h3 - 3 * h2 + 1) * p[k] + (h3 - 2 * h2 + h) * dt * m[k] + (-2 * h3 + 3 * h2) * p[k + 1]
            + (h3 - h2) * dt * m[k + 1])


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
    log; cx, cy: monotone cubic. Every key must have the same image size."""
    if not keys:
        raise GBViewerError("keyframes: none given")
    w, h = keys[0].camera.width, keys[0].camera.height
    if any((k.camera.width, k.camera.height) != (w, h) for k in keys):
        raise GBViewerError("keyframes: every key's camera must have the same image size")
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
    scal = np.stack([[math.log(k.rate), math.log(k.camera.fx), math.log(k.camera.fy), k.camera.cx, k.camera.cy]
                     for k in keys])
    m_pos, m_scal = _catmull_rom_tangents(ts, pos), _monotone_tangents(ts, scal)
    out = []
    for t in times:
        t = float(np.clip(t, ts[0], ts[-1]))
        k, hh = _segment(ts, t)
        c = _hermite(ts, pos, m_pos, k, hh)
        q = slerp(slerp(qs[k], qs[k + 1], hh), slerp(ctrl[k], ctrl[k + 1], hh), 2 * hh * (1 - hh))
        lr, lfx, lfy, cx, cy = _hermite(ts, scal, m_scal, k, hh)
        R = matrix_from_quat(q)
        cam = replace(keys[0].camera, R=R, t=-R @ c, fx=math.exp(lfx), fy=math.exp(lfy), cx=cx, cy=cy,
                      name=f"keyframes@{t:g}")
        out.append(Keyframe(cam, math.exp(lr), t))
    return out


def keyframe_path(keys: Sequence[Keyframe], frames: int) -> list[PathFrame]:
    """`frames` frames evenly spaced in time from the first key to the last (both included)."""
    ts = key_times(keys)
    if frames < 1:
        raise GBViewerError(f"a video needs at least one frame, got {frames}")
    times = [ts[0]] if frames == 1 else [ts[0] + (ts[-1] - ts[0]) * i / (frames - 1) for i in range(frames)]
    if frames > 1:
        times[-1] = ts[-1]
    out = []
    for key in interpolate_keyframes(keys, times):
        cam = key.camera
        out.append(PathFrame(cam.at_sampling_rate(key.rate) if key.rate != 1 else cam, key.rate, cam.width,
                             cam.height, 1.0, (cam.cx, cam.cy)))
    return out


def _vec(e: dict, name: str, n: int, where: str) -> np.ndarray:
    try:
        v = np.asarray(e[name], dtype=np.float64)
        return v.reshape(n) if n != 9 else v.reshape(3, 3)
    except (TypeError, ValueError) as exc:
        raise GBViewerError(f"{where}: {name!r} must be {'a 3x3 matrix' if n == 9 else f'{n} numbers'} ({exc})") \
            from None


def load_keyframes(path: str | Path, base: Camera, scene: Scene | None = None, up: str = "-y") -> list[Keyframe]:
    """Keyframes from JSON: {"keyframes": [KEY, ...]} or a bare list of KEYs. A KEY gives a pose as one of

      {"R": 3x3, "t": [3]}                    world-to-camera, as gb.Camera (x_cam = R x + t; OpenCV axes)
      {"rotation": 3x3, "position": [3]}      camera-to-world rotation and centre, as a 3DGS cameras.json entry
      {"position": [3], "look_at": [3], "up": [3]}   eye, target and world up (default: the --up axis)
      {"orbit": [azimuth, elevation, distance]}      degrees, scene units (distance <= 0 or null: auto framing)

    and optionally "time" (seconds; give it to all keys or none), "rate" (sampling rate rendered at, default 1:
    rendered at that rate and shown nearest-upscaled), "fov_y_deg" or "fx", "fy", "cx", "cy" (pixels at the pane
    size; default: the base camera's intrinsics). The pane size is the base camera's.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GBViewerError(f"{path}: cannot read keyframes: {exc}") from None
    entries = doc.get("keyframes") if isinstance(doc, dict) else doc
    if not isinstance(entries, list) or not entries:
        raise GBViewerError(f"{path}: expected a non-empty list of keyframes (or {{\"keyframes\": [...]}})")
    keys = []
    for i, e in enumerate(entries):
        where = f"{path}: keyframe {i}"
        if not isinstance(e, dict):
            raise GBViewerError(f"{where}: expected an object")
        try:
            if "R" in e:
                R, t = _vec(e, "R", 9, where), _vec(e, "t", 3, where)
            elif "rotation" in e:
                R = _vec(e, "rotation", 9, where).T
                t = -R @ _vec(e, "position", 3, where)
            elif "look_at" in e:
                u = _vec(e, "up", 3, where) if "up" in e else np.array(UP_AXES[up])
                c = Camera.look_at(_vec(e, "position", 3, where), _vec(e, "look_at", 3, where), u)
                R, t = c.R, c.t
            elif "orbit" in e:
                if scene is None:
                    raise GBViewerError(f"{where}: 'orbit' keys need the scene")
                az, el, dist = (list(e["orbit"]) + [None])[:3]
                c = orbit_camera(scene, float(az), float(el), float(dist) if dist and float(dist) > 0 else None,
                                 base.width, base.height, up=up)
                R, t = c.R, c.t
            else:
                raise GBViewerError(f"{where}: no pose; give R and t, rotation and position, position and look_at, "
                                    "or orbit")
            intr = dict(fx=base.fx, fy=base.fy, cx=base.cx, cy=base.cy)
            if "fov_y_deg" in e:
                f = 0.5 * base.height / math.tan(math.radians(float(e["fov_y_deg"])) / 2)
                intr = dict(fx=f, fy=f, cx=base.width / 2, cy=base.height / 2)
            intr.update({k: float(e[k]) for k in ("fx", "fy", "cx", "cy") if k in e})
            cam = replace(base, R=R, t=t, name=f"key{i}", **intr)
            rate = float(Fraction(str(e.get("rate", 1))))
            time_ = float(e["time"]) if e.get("time") is not None else None
        except CameraError as exc:
            raise GBViewerError(f"{where}: {exc}") from None
        except (TypeError, ValueError, ZeroDivisionError) as exc:
            raise GBViewerError(f"{where}: {exc}") from None
        keys.append(Keyframe(cam, rate, time_))
    key_times(keys)
    return keys


def keyframes_to_json(keys: Sequence[Keyframe]) -> dict:
    """The JSON document `load_keyframes` reads back (world-to-camera R, t and the intrinsics of every key)."""
    return {"keyframes": [
        {"R": k.camera.R.tolist(), "t": k.camera.t.tolist(), "fx": k.camera.fx, "fy": k.camera.fy,
         "cx": k.camera.cx, "cy": k.camera.cy, "rate": k.rate, **({"time": k.time} if k.time is not None else {})}
        for k in keys]}


def camera_path(kind: str | Path, base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0,
                scene: Scene | None = None, up: str = "-y") -> list[PathFrame]:
    """'zoom', 'dolly' (focus: the scene's centre) or 'rate' from `start` to `end`, or a keyframes JSON file."""
    if str(kind) == "zoom":
        return zoom_path(base, frames, start, end)
    if str(kind) == "dolly":
        if scene is None:
            raise GBViewerError("dolly: needs the scene (its centre sets the focus depth)")
        return dolly_path(base, frames, start, end, scene_focus_depth(scene, base))
    if str(kind) == "rate":
        return rate_path(base, frames, start, end)
    if str(kind).lower().endswith(".json") or Path(kind).is_file():
        return keyframe_path(load_keyframes(kind, base, scene, up), frames)
    raise GBViewerError(f"path {str(kind)!r}; expected zoom, dolly, rate or a keyframes FILE.json")


# --------------------------------------------------------------------------------------------------------------
# video


@dataclass(frozen=True)
class VideoInfo:
    path: Path
    frames: int
    width: int
    height: int
    fps: float
    elapsed_s: float  # rendering and encoding, wall clock


def _frame_lines(pf: PathFrame) -> Callable[[Cell], list[str]]:
    def lines(cell: Cell) -> list[str]:
        h, w = cell.rgb.shape[:2]
        size = f"  (rendered {w}x{h})" if (w, h) != (pf.width, pf.height) else ""
        return [cell.stats.mode or cell.settings.label, f"sampling rate {format_rate(pf.rate)}{size}"]
    return lines


def compose_video_frame(cells: list[Cell], pf: PathFrame, inset: tuple[float, float, float, float] | None = None
                        ) -> Image.Image:
    """The panes of one frame side by side, each captioned below with its mode and the sampling rate, the inset
    region (x1 pixels) following the content; even canvas size."""
    return compose_grid([cells], pf.width, pf.height, GAP, captions="below", lines=_frame_lines(pf),
                        inset=pf.map_box(inset) if inset is not None else None, even=True)


def video_layout(pf: PathFrame, n_modes: int) -> GridLayout:
    """Where `compose_video_frame` puts the panes (GridLayout.origin(0, i) is pane i's top-left pixel)."""
    from .figure import caption_font_size

    return GridLayout(1, n_modes, pf.width, pf.height, GAP, GridLayout.caption_height_for(2, caption_font_size(
        pf.height)), even=True)


def record_video(scene: Scene, camera_path: Sequence[PathFrame | Camera], settings_list: Sequence[RenderSettings],
                 out: str | Path, *, fps: float = 30.0, backend: str = "cpu",
                 inset: tuple[float, float, float, float] | None = None, crf: int = DEFAULT_CRF,
                 preset: str = "medium", force: bool = False, progress: Callable[[int, int], None] | None = None,
                 cancel=None) -> VideoInfo:
    """Render every frame of `camera_path` in every mode of `settings_list` side by side and write an H.264 MP4.

    camera_path: PathFrames (`zoom_path`, `dolly_path`, `rate_path`, `keyframe_path`, `camera_path`) or plain
    Cameras (rate 1, pane = the camera's size); every frame must have the same pane size. Frames are rendered,
    composed and piped to ffmpeg (imageio-ffmpeg's bundled one: libx264, yuv420p, constant quality `crf`) one at a
    time, so memory does not grow with the length; the CPU backend uses every core for each frame.

    Safe to call from a background thread with the cpu backend (the native renderer keeps no state between calls
    and releases the GIL; a GL backend's context belongs to the thread that made it):
      progress(done, total) is called after each frame is encoded (from the calling thread);
      cancel: anything with is_set() (a threading.Event), checked before each render; when set, ffmpeg is stopped,
      the partial file removed and `Cancelled` raised.
    The video is written to a temporary file beside `out` and renamed onto it at the end: an exception, Ctrl-C
    or cancel leaves neither. Refuses to overwrite an existing `out` unless `force`.
    Returns a VideoInfo (path, frame count, frame size, fps, wall time).
    """
    import imageio_ffmpeg

    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise GBViewerError(f"{out}: output must end in .mp4")
    if out.exists() and not force:
        raise GBViewerError(f"{out}: exists; pass --force to overwrite")
    frames = [pf if isinstance(pf, PathFrame) else PathFrame.of(pf) for pf in camera_path]
    if not frames:
        raise GBViewerError("the camera path has no frames")
    if not settings_list:
        raise GBViewerError("no modes given")
    if any((pf.width, pf.height) != (frames[0].width, frames[0].height) for pf in frames):
        raise GBViewerError("every frame of the camera path must have the same pane size")
    if not (fps > 0 and math.isfinite(fps)):
        raise GBViewerError(f"fps must be > 0, got {fps}")
    renderer = get_renderer(scene, backend)
    size: list[int] = []
    t0 = time.perf_counter()

    def write(tmp: Path) -> None:
        writer = None
        try:
            for i, pf in enumerate(frames):
                cells = []
                for s in settings_list:
                    if cancel is not None and cancel.is_set():
                        raise Cancelled("video cancelled; nothing written")
                    frame = renderer.render(pf.camera, s)
                    cells.append(Cell(s, pf.rate, frame.rgb, frame.stats))
                img = np.asarray(compose_video_frame(cells, pf, inset))
                if writer is None:
                    size[:] = [img.shape[1], img.shape[0]]
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp), tuple(size), fps=Fraction(fps).limit_denominator(1001), codec="libx264",
                        pix_fmt_out="yuv420p", quality=None, macro_block_size=1,
                        output_params=["-crf", str(int(crf)), "-preset", preset, "-movflags", "+faststart"])
                    writer.send(None)
                writer.send(np.ascontiguousarray(img))
                if progress is not None:
                    progress(i + 1, len(frames))
        finally:
            if writer is not None:
                writer.close()  # ffmpeg finishes (or is stopped) before the file is renamed or removed
        written = imageio_ffmpeg.count_frames_and_secs(str(tmp))[0]  # imageio does not check ffmpeg's exit status
        if written != len(frames):
            raise GBViewerError(f"ffmpeg wrote {written} of {len(frames)} frames; see its messages above")

    atomic_write(out, write, force)
    return VideoInfo(out, len(frames), size[0], size[1], float(fps), time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------------------------
# comparison figure


def reference_psnr(reference_x1: np.ndarray, rgb: np.ndarray, rate: float) -> float | None:
    """PSNR of a render at rate 1/k against the x1 scalar render box-downsampled by k (the benchmark's zoom-out
    reference); None where there is none (rates > 1, 1/rate not an integer, sizes that do not divide)."""
    from .bench import box_downsample, psnr

    if rate > 1:
        return None
    k = round(1.0 / rate)
    if not math.isclose(k, 1.0 / rate, rel_tol=1e-9):
        return None
    ref = box_downsample(reference_x1, k) if k > 1 else reference_x1
    if ref.shape != rgb.shape:
        return None
    return psnr(rgb, ref)


@dataclass
class Comparison:
    image: Image.Image
    cells: list[list[Cell]]  # rows: rates; columns: settings
    psnr: list[list[float | None]]
    layout: GridLayout  # layout.origin(row, col): where each cell's nearest-upscaled render is in `image`


def compare_figure(scene: Scene, camera: Camera, settings_list: Sequence[RenderSettings], rates: Sequence[float],
                   backend: str = "cpu", inset: tuple[float, float, float, float] | None = None) -> Comparison:
    """Grid of modes (columns) x rates (rows) like the paper's figures: each cell rendered at camera
    .at_sampling_rate(rate), nearest-upscaled to the camera's size, captioned below with mode, rate and size and
    with its PSNR against the zoom-out reference (`reference_psnr`) and render time. `inset` (x, y, w, h in x1
    pixels) is magnified into each cell's corner."""
    from .figure import caption_font_size

    settings_list, rates = list(settings_list), list(rates)
    if not settings_list or not rates:
        raise GBViewerError("compare: give at least one mode and one rate")
    cells = render_grid(scene, camera, settings_list, rates, backend)
    ref_settings = replace(settings_list[0], mode=Mode.SCALAR, supersample=1, debug="none")
    ref = next((c.rgb for row in cells for c in row if c.rate == 1.0 and c.settings == ref_settings), None)
    if ref is None and any(r <= 1 for r in rates):
        ref = get_renderer(scene, backend).render(camera, ref_settings).rgb
    psnrs = [[reference_psnr(ref, c.rgb, c.rate) if ref is not None else None for c in row] for row in cells]
    notes = {id(c): p for row, prow in zip(cells, psnrs) for c, p in zip(row, prow)}

    def lines(cell: Cell) -> list[str]:
        h, w = cell.rgb.shape[:2]
        p = notes[id(cell)]
        ms = f"{cell.stats.total_ms:.0f} ms"
        if p is None:
            note = f"no reference  {ms}"
        elif math.isinf(p):
            note = f"reference  {ms}"
        else:
            note = f"PSNR {p:.2f} dB  {ms}"
        return [f"{cell.stats.mode or cell.settings.label}  {format_rate(cell.rate)} ({w}x{h})", note]

    img = compose_grid(cells, camera.width, camera.height, GAP, captions="below", lines=lines, inset=inset)
    layout = GridLayout(len(rates), len(settings_list), camera.width, camera.height, GAP,
                        GridLayout.caption_height_for(2, caption_font_size(camera.height)))
    assert layout.size == img.size
    return Comparison(img, cells, psnrs, layout)


def write_comparison(out: str | Path, comparison: Comparison, force: bool = False) -> Path:
    """The figure as PNG, atomically; refuses to overwrite without `force`."""
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise GBViewerError(f"{out}: output must end in .png")
    return save_image(out, comparison.image, force)
