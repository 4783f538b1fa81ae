"""Camera paths for zoom videos: a steady zoom (focal length), a dolly (the camera along its axis), a sampling-rate
sweep (same view, rendered at each rate and nearest-resized to the pane), or keyframes (`gbviewer.model.keyframes`).

Sampling rate s: the content is sampled s times as densely per axis as in the x1 view (s = 1/8: zoomed out 8x).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.errors import GBViewerError
from ..core.validate import integer, real
from .camera import Camera
from .keyframes import Keyframe, interpolate_keyframes, key_times, load_keyframes
from .nerfstudio_paths import NerfstudioPath
from .scene import Scene

PATHS = ("zoom", "dolly", "rate")
DEFAULT_SECONDS = 4.0  # length of a path when neither frames nor seconds are given (and keyframes have no times)
MAX_FRAMES = 100_000  # default limit of a path's length (`camera_path`'s max_frames, `gbviewer video --max-frames`)


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
    start = real(start, "first sampling rate", lo=0.0, lo_open=True)
    end = real(end, "last sampling rate", lo=0.0, lo_open=True)
    frames = integer(frames, "frames of the video", lo=1)
    if frames == 1:
        return [start]
    return [start * (end / start) ** (i / (frames - 1)) for i in range(frames - 1)] + [end]


def zoom_path(base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0) -> list[PathFrame]:
    """The focal length (orthographic: the pixels per unit) goes from start x to end x the base camera's,
    geometrically; the pane size stays.

    At rate s the content appears s times its x1 size (about the principal point), so it is sampled at rate s."""
    return [
        PathFrame(replace(base, fx=base.fx * s, fy=base.fy * s), s, base.width, base.height, s, (base.cx, base.cy))
        for s in geometric_rates(start, end, frames)
    ]


def dolly_path(
    base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0, focus_depth: float = 1.0
) -> list[PathFrame]:
    """The camera moves along its optical axis so that things at `focus_depth` (camera z of the base camera)
    appear s times their x1 size: it stands at depth focus_depth / s from them. Nearer and farther things scale
    differently (that is what distinguishes a dolly from a zoom). An orthographic camera's image does not change
    with its distance: an error (its zoom scales fx, fy)."""
    if base.orthographic:
        raise GBViewerError(
            "dolly: an orthographic camera sees the same image from any distance; use --path zoom "
            "(it scales the pixels per unit)"
        )
    focus_depth = real(focus_depth, "dolly: focus depth", lo=0.0, lo_open=True)
    out = []
    for s in geometric_rates(start, end, frames):
        t = base.t + np.array([0.0, 0.0, focus_depth * (1.0 / s - 1.0)])
        out.append(PathFrame(replace(base, t=t), s, base.width, base.height, s, (base.cx, base.cy)))
    return out


def rate_path(base: Camera, frames: int, start: float = 1.0, end: float = 1.0 / 8.0) -> list[PathFrame]:
    """The view stays; frame i is rendered at sampling rate s_i (`Camera.at_sampling_rate`, so the image size
    changes in whole-pixel steps) and shown resized to the pane with nearest filtering."""
    return [
        PathFrame(base.at_sampling_rate(s), s, base.width, base.height, 1.0, (base.cx, base.cy))
        for s in geometric_rates(start, end, frames)
    ]


def scene_focus_depth(scene: Scene, camera: Camera, what: str = "dolly", hint: str = "use --path zoom") -> float:
    """Camera depth of the centre of the scene's robust bounds (the dolly's focus); an error naming `what`, with
    `hint`, when it is not in front of the camera."""
    lo, hi = scene.robust_bounds()
    z = float((camera.R @ ((np.asarray(lo, np.float64) + hi) / 2) + camera.t)[2])
    if not z > camera.near:
        raise GBViewerError(f"{what}: the scene's centre is not in front of the camera (depth {z:.3g}); {hint}")
    return z


def keyframe_path(keys: Sequence[Keyframe], frames: int) -> list[PathFrame]:
    """`frames` frames evenly spaced in time from the first key to the last (both included)."""
    ts = key_times(keys)
    frames = integer(frames, "frames of the video", lo=1)
    times = [ts[0]] if frames == 1 else [ts[0] + (ts[-1] - ts[0]) * i / (frames - 1) for i in range(frames)]
    if frames > 1:
        times[-1] = ts[-1]
    out = []
    for key in interpolate_keyframes(keys, times):
        cam = key.camera
        out.append(
            PathFrame(
                cam.at_sampling_rate(key.rate) if key.rate != 1 else cam,
                key.rate,
                cam.width,
                cam.height,
                1.0,
                (cam.cx, cam.cy),
            )
        )
    return out


def path_length(
    frames: int | None,
    fps: float = 30.0,
    seconds: float | None = None,
    keys: Sequence[Keyframe] | None = None,
    max_frames: int = MAX_FRAMES,
) -> int:
    """A path's frame count: `frames`; without it `seconds` x fps, or the keyframes' timed span x fps (+ 1, both
    ends), or DEFAULT_SECONDS x fps; more than `max_frames` is an error."""
    what = f"frames of the video (at most {max_frames}; --max-frames raises the limit)"
    if frames is None:
        if seconds is not None:
            length = max(1.0, real(seconds, "seconds", lo=0.0, lo_open=True) * fps)
        elif keys is not None and keys[0].time is not None:
            length = (keys[-1].time - keys[0].time) * fps + 1
        else:
            length = DEFAULT_SECONDS * fps
        frames = round(real(length, what))
    return integer(frames, what, lo=1, hi=max_frames)


def nerfstudio_frames(
    p: NerfstudioPath, frames: int | None = None, seconds: float | None = None, max_frames: int = MAX_FRAMES
) -> list[PathFrame]:
    """The frames of a camera_path.json: its interpolated camera_path list as ns-render renders it, or without one
    its keyframes interpolated here (`keyframe_path`; length as `path_length`, at the file's fps). `frames` or
    `seconds` with a camera_path list is an error: the file sets them."""
    if p.frames:
        if frames is not None or seconds is not None:
            raise GBViewerError("the camera path file lists its frames; drop --frames and --seconds")
        integer(
            len(p.frames),
            f"frames of the camera path (at most {max_frames}; --max-frames raises the limit)",
            hi=max_frames,
        )
        return [PathFrame.of(c) for c in p.frames]
    return keyframe_path(
        p.keys, path_length(frames, p.fps, seconds if seconds is not None else p.seconds, p.keys, max_frames)
    )


def camera_path(
    kind: str | Path,
    base: Camera,
    frames: int | None,
    start: float = 1.0,
    end: float = 1.0 / 8.0,
    scene: Scene | None = None,
    up: str = "-y",
    *,
    fps: float = 30.0,
    seconds: float | None = None,
    max_frames: int = MAX_FRAMES,
) -> list[PathFrame]:
    """'zoom', 'dolly' (focus: the scene's centre) or 'rate' from `start` to `end`, or a keyframes JSON file.

    Length: `frames`; without it `seconds` x fps, or a keyframes file's timed span x fps (+ 1, both ends), or
    DEFAULT_SECONDS x fps; more than `max_frames` is an error raised before any frame is made."""
    fps = real(fps, "fps", lo=0.0, lo_open=True)
    keyed = str(kind) not in PATHS
    if keyed and not (str(kind).lower().endswith(".json") or Path(kind).is_file()):
        raise GBViewerError(f"path {str(kind)!r}; expected zoom, dolly, rate or a keyframes FILE.json")
    keys = load_keyframes(kind, base, scene, up) if keyed else None
    frames = path_length(frames, fps, seconds, keys, max_frames)
    if keys is not None:
        return keyframe_path(keys, frames)
    if str(kind) == "zoom":
        return zoom_path(base, frames, start, end)
    if str(kind) == "dolly":
        if scene is None:
            raise GBViewerError("dolly: needs the scene (its centre sets the focus depth)")
        return dolly_path(base, frames, start, end, scene_focus_depth(scene, base))
    return rate_path(base, frames, start, end)
