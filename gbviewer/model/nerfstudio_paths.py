"""nerfstudio's camera_path.json: read and written with its keyframes and its interpolated `camera_path`.

The layout is the one nerfstudio's viewer writes and `ns-render camera-path` reads (nerfstudio-project/nerfstudio:
nerfstudio/viewer/render_panel.py `_write_json` and the "Load Path" handler, nerfstudio/cameras/camera_paths.py
`get_path_from_json`, nerfstudio/scripts/render.py `RenderCameraPath`):

  render_width, render_height   the image size in pixels; the principal point is its centre
  camera_type                   "perspective" ("fisheye", "equirectangular", ... are refused)
  fps, seconds                  ns-render writes len(camera_path) / seconds frames a second
  keyframes: [{matrix, fov, aspect, override_transition_enabled, override_transition_sec}]
  camera_path: [{camera_to_world, fov, aspect}]

`matrix` and `camera_to_world` are camera-to-world 4x4 matrices, row-major, flattened to 16 numbers, of an OpenGL
camera (x right, y up, looking down -z) in the file's world coordinates (taken as the scene's); `fov` is the
vertical field of view in degrees. Keyframe k > 0 comes `override_transition_sec` (when enabled) or
`default_transition_sec` after key k - 1; `is_cycle` adds key 0 once more at the end.
"orthographic" is gbviewer's own camera_type (nerfstudio has none): each entry then gives `view_height`, the world
units the image height spans, instead of `fov`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..core.errors import CameraError, InvalidValue
from ..core.files import atomic_write
from ..core.validate import array, field, integer, read_json, real
from .camera import MAX_IMAGE_SIZE, Camera, focal_from_fov, fov_of
from .keyframes import MAX_FOV_DEG, Keyframe, interpolate_keyframes, key_times

GL_TO_CV = np.diag([1.0, -1.0, -1.0])  # camera axes: OpenGL (y up, -z forward) <-> OpenCV (y down, +z forward)
CAMERA_TYPES = ("perspective", "orthographic")
DEFAULT_TRANSITION_S = 0.5  # the viewer's fallback when a file has no default_transition_sec ("Load Path")


@dataclass(frozen=True)
class NerfstudioPath:
    """A camera_path.json: its keyframes (times in seconds from key 0) and its interpolated frames, all at the
    render size; `fps` and `seconds` as the file gives them."""

    keys: tuple[Keyframe, ...]
    frames: tuple[Camera, ...]
    fps: float
    seconds: float

    @property
    def size(self) -> tuple[int, int]:
        cam = (self.frames or [k.camera for k in self.keys])[0]
        return cam.width, cam.height

    @property
    def frame_rate(self) -> float:
        """Frames a second of the rendered video, as ns-render makes it: len(camera_path) / seconds."""
        return len(self.frames) / self.seconds if self.frames else self.fps


def is_nerfstudio_path(doc: Any) -> bool:
    """Whether a parsed JSON document is in nerfstudio's layout (an object with camera_path or render_height)."""
    return isinstance(doc, dict) and ("camera_path" in doc or "render_height" in doc)


def camera_from_c2w(c2w: object, lens: float, width: int, height: int, projection: str, where: str) -> Camera:
    """A centred camera from a flattened camera-to-world OpenGL matrix; `lens`: the vertical field of view in
    degrees (perspective) or the world units the height spans (orthographic)."""
    m = array(c2w, f"{where}: camera-to-world matrix", (16,), f32=True).reshape(4, 4)
    if np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-6:
        raise InvalidValue(f"{where}: camera-to-world matrix: expected a last row of 0, 0, 0, 1, got {m[3].tolist()}")
    R = (m[:3, :3] @ GL_TO_CV).T  # rows: the OpenCV camera's axes in the world
    f = focal_from_fov(lens, height) if projection == "perspective" else height / lens
    try:
        return Camera(width, height, f, f, width / 2, height / 2, R, -R @ m[:3, 3], projection=projection)
    except CameraError as exc:
        raise InvalidValue(f"{where}: {exc}") from None


def c2w_of(camera: Camera) -> list[float]:
    """The flattened camera-to-world OpenGL matrix of a camera (`camera_from_c2w`'s inverse)."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(camera.R, np.float64).T @ GL_TO_CV
    m[:3, 3] = camera.position
    return m.ravel().tolist()


def lens_entry(camera: Camera) -> dict[str, float]:
    """{"fov": degrees} of a perspective camera, {"view_height": world units} of an orthographic one."""
    if camera.orthographic:
        return {"view_height": camera.height / camera.fy}
    return {"fov": fov_of(camera)}


def _entry_camera(e: object, key: str, where: str, size: tuple[int, int], projection: str) -> Camera:
    if not isinstance(e, dict):
        raise InvalidValue(f"{where}: expected a JSON object, got {type(e).__name__}")
    if projection == "perspective":
        lens = real(field(e, "fov", where), f"{where}: 'fov'", lo=0, lo_open=True, hi=MAX_FOV_DEG)
    else:
        lens = real(field(e, "view_height", where), f"{where}: 'view_height'", lo=0, lo_open=True, f32=True)
    return camera_from_c2w(field(e, key, where), lens, *size, projection, where)


def load_nerfstudio_path(path: str | Path, size: tuple[int, int] | None = None) -> NerfstudioPath:
    """A camera_path.json (the module's layout); `size`: render at this (width, height) instead of the file's
    render size (the vertical field of view kept). Every value is checked: a bad one is a one-line
    `InvalidValue` naming the file and the field."""
    path = Path(path)
    doc = read_json(path)
    if not is_nerfstudio_path(doc):
        raise InvalidValue(
            f"{path}: expected nerfstudio's camera_path.json (an object with render_width, "
            f"render_height and camera_path or keyframes)"
        )
    kind = str(doc.get("camera_type", "perspective")).lower()
    if kind not in CAMERA_TYPES:
        raise InvalidValue(
            f"{path}: camera_type {kind!r:.40}: gbviewer renders perspective or orthographic cameras only"
        )
    if size is None:
        size = tuple(
            integer(_whole(field(doc, k, str(path)), f"{path}: '{k}'"), f"{path}: '{k}'", lo=1, hi=MAX_IMAGE_SIZE)
            for k in ("render_width", "render_height")
        )
    fps = real(field(doc, "fps", str(path)), f"{path}: 'fps'", lo=0, lo_open=True)
    seconds = real(field(doc, "seconds", str(path)), f"{path}: 'seconds'", lo=0, lo_open=True)
    frames = tuple(
        _entry_camera(e, "camera_to_world", f"{path}: camera_path {i}", size, kind)
        for i, e in enumerate(_list(doc, "camera_path", path))
    )
    entries = _list(doc, "keyframes", path)
    keys = [_entry_camera(e, "matrix", f"{path}: keyframe {i}", size, kind) for i, e in enumerate(entries)]
    default_s = real(
        doc.get("default_transition_sec", DEFAULT_TRANSITION_S), f"{path}: 'default_transition_sec'", lo=0, lo_open=True
    )
    times = [0.0]
    for i, e in enumerate(entries[1:] + (entries[:1] if doc.get("is_cycle") is True and entries else []), 1):
        s = e.get("override_transition_sec") if e.get("override_transition_enabled") is True else None
        times.append(
            times[-1]
            + (
                default_s
                if s is None
                else real(s, f"{path}: keyframe {i % len(entries)}: 'override_transition_sec'", lo=0, lo_open=True)
            )
        )
    if doc.get("is_cycle") is True and keys:
        keys.append(keys[0])
    if not frames and not keys:
        raise InvalidValue(f"{path}: neither camera_path nor keyframes has an entry")
    return NerfstudioPath(tuple(Keyframe(c, 1.0, t) for c, t in zip(keys, times)), frames, fps, seconds)


def _whole(value: object, what: str) -> object:
    """A size that nerfstudio may write as a float (1080.0) as the integer it is; anything else as given."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def _list(doc: dict, key: str, path: Path) -> list:
    value = doc.get(key, [])
    if not isinstance(value, list):
        raise InvalidValue(f"{path}: '{key}': expected a list, got {type(value).__name__}")
    return value


def path_from_keyframes(keys: Sequence[Keyframe], fps: float = 30.0, seconds: float | None = None) -> NerfstudioPath:
    """A NerfstudioPath of our keyframes (times from key 0; untimed keys one second apart unless `seconds` spreads
    them): its frames sampled as nerfstudio's viewer does, int(fps x seconds) of them at i / fps."""
    if not keys:
        raise InvalidValue("camera path: no keyframes")
    ts = key_times(keys)
    span = float(ts[-1] - ts[0])
    seconds = real(seconds if seconds is not None else span, "seconds", lo=0, lo_open=True)
    scale = seconds / span if span > 0 and keys[0].time is None else 1.0
    timed = [Keyframe(k.camera, 1.0, float(t - ts[0]) * scale) for k, t in zip(keys, ts)]
    n = int(real(fps, "fps", lo=0, lo_open=True) * seconds)
    frames = tuple(k.camera for k in interpolate_keyframes(timed, [i / fps for i in range(n)]))
    return NerfstudioPath(tuple(timed), frames, fps, seconds)


def nerfstudio_json(p: NerfstudioPath) -> dict:
    """The camera_path.json document of a path (`load_nerfstudio_path` reads it back)."""
    cams = [k.camera for k in p.keys] + list(p.frames)
    width, height = p.size
    aspect = width / height
    ts = [k.time or 0.0 for k in p.keys]
    gaps = [None] + [b - a for a, b in zip(ts, ts[1:])]  # key i's transition, from key i - 1
    default = gaps[1] if len(gaps) > 1 else DEFAULT_TRANSITION_S
    own = [g is not None and not math.isclose(g, default, rel_tol=1e-9) for g in gaps]
    return {
        "default_fov": lens_entry(cams[0]).get("fov", 50.0),
        "default_transition_sec": default,
        "keyframes": [
            {
                "matrix": c2w_of(k.camera),
                **lens_entry(k.camera),
                "aspect": aspect,
                "override_transition_enabled": own[i],
                "override_transition_sec": gaps[i] if own[i] else None,
            }
            for i, k in enumerate(p.keys)
        ],
        "camera_type": cams[0].projection,
        "render_width": width,
        "render_height": height,
        "fps": p.fps,
        "seconds": p.seconds,
        "is_cycle": False,
        "smoothness_value": 0.0,
        "camera_path": [{"camera_to_world": c2w_of(c), **lens_entry(c), "aspect": aspect} for c in p.frames],
    }


def save_nerfstudio_path(p: NerfstudioPath, out: str | Path, force: bool = False) -> Path:
    """Write `nerfstudio_json(p)` to `out` atomically (an existing file only with `force`)."""
    text = json.dumps(nerfstudio_json(p), indent=1)
    return atomic_write(out, lambda tmp: Path(tmp).write_text(text), force)
