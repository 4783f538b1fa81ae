"""The viewer's state and the actions that the panel, the menus and the keys trigger. No imgui, glfw or OpenGL here:
all of it is unit-tested without a window (tests/app/test_state.py); `window.ViewerApp` draws it."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from ..camera import UP_AXES, Camera, load_cameras_json
from ..errors import GBViewerError
from ..render import Frame, Mode, RenderSettings
from ..scene import Scene
from .camera_control import CameraController
from .dataset import DatasetViews
from .layout import PANEL_W, Rect, fit_aspect, pane_rects
from .loading import SceneLoader
from .rates import clamp_rate, render_size, step_rate
from .recording import VideoJob
from .screenshots import shot_name
from .settings import MAX_PANES, MODE_NAMES, PANE_NAMES, AppSettings, PaneSettings, add_recent
from .worker import RenderJob

MOVING_HOLD_S = 0.25  # the camera counts as moving this long after the last change
VIDEO_PANE_W = 480
Level = Literal["info", "warn", "error"]  # of a status-bar message


def is_cameras_file(path: str | Path) -> bool:
    """A file the viewer opens as training cameras rather than a scene."""
    return Path(path).suffix.lower() == ".json"


class RateMeter:
    """Events per second over the last `span` seconds."""

    def __init__(self, span: float = 2.0) -> None:
        self.span = span
        self.times: deque[float] = deque()

    def tick(self, t: float | None = None) -> None:
        t = time.perf_counter() if t is None else t
        self.times.append(t)
        while self.times and self.times[0] < t - self.span:
            self.times.popleft()

    def rate(self, now: float | None = None) -> float:
        now = time.perf_counter() if now is None else now
        ts = [t for t in self.times if t >= now - self.span]
        if len(ts) < 2:
            return 0.0
        return (len(ts) - 1) / max(1e-9, ts[-1] - ts[0])


@dataclass
class Shown:
    """What one pane part (its whole image, or one side of a split) shows: the last finished frame."""

    texture: object = None
    frame: Frame | None = None
    job: RenderJob | None = None
    view: str = ""
    legend: str = ""
    image: np.ndarray | None = None  # uint8 (H, W, 3) as uploaded
    error: str = ""
    progress: float | None = None  # fraction of a refining frame's tiles on screen; None once final
    stage: str = ""  # what is on screen: "preview", "quick" (x1 sample), "refining", "final"
    pacing: dict[str, float] = field(default_factory=dict)  # ms from a request to its "preview"/"tiles"/"final"


@dataclass
class PaneState:
    """One pane: where it is, its render size, what it shows and the requests it has in flight."""

    index: int
    parts: dict[str, Shown] = field(default_factory=lambda: {"a": Shown(), "b": Shown()})
    submitted: dict = field(default_factory=dict)  # part -> key of the last request
    fps: dict[str, RateMeter] = field(default_factory=lambda: {"a": RateMeter(), "b": RateMeter()})
    ms_per_px: dict = field(default_factory=dict)  # (part, mode, supersample, backend) -> cost of a full render
    rect: Rect = Rect(0, 0, 1, 1)
    render_size: tuple[int, int] = (1, 1)  # at the current rate, without a preview drop

    @property
    def name(self) -> str:
        return PANE_NAMES[self.index]

    def forget(self) -> None:
        """Drop what belongs to the previous scene: its frames, requests and measured costs."""
        self.parts = {"a": Shown(), "b": Shown()}
        self.submitted.clear()
        self.ms_per_px.clear()


class AppState:
    """Scene, cameras, panes and their settings, and the actions on them."""

    def __init__(self, settings: AppSettings, cameras: str | Path | None = None) -> None:
        self.settings = settings
        self.controller = CameraController(fov_y_deg=settings.fov_y_deg, up=settings.up,
                                           projection=settings.projection)
        self.scene: Scene | None = None
        self.scene_path: Path | None = None
        self.cameras: list[Camera] = []
        self.cameras_path: Path | None = None
        self.cam_index = -1
        self.dataset = DatasetViews(self.message)  # the training photos, their views, the snapped one
        self.loader: SceneLoader | None = None
        self.load_error = self.load_error_short = ""
        self.fly = False
        self.show_help = False
        self.last_move = 0.0
        self.messages: list[tuple[float, str, Level]] = []  # (time, text, level)
        self.panes = [PaneState(i) for i in range(MAX_PANES)]
        self.viewport = Rect(PANEL_W, 0, 1, 1)
        self.scale = (1.0, 1.0)  # framebuffer pixels per window coordinate
        self.hover: tuple[int, float, float] | None = None  # pane, u, v under the cursor
        self.dragging_split: int | None = None
        self.needs_reset = False  # frame the camera once the panes have their size
        self.pending_cameras = cameras  # opened once the first scene is in
        self.video: VideoJob | None = None
        self.video_frames = 90

    def message(self, text: str, level: Level = "info") -> None:
        self.messages.append((time.perf_counter(), text, level))
        self.messages = self.messages[-6:]

    # ---- opening ------------------------------------------------------------------------------------------------

    def open(self, path: str | Path) -> None:
        """Open a scene (in the background) or, for a .json, training cameras."""
        path = Path(path).expanduser()
        if is_cameras_file(path):
            self.open_cameras(path)
            return
        self.load_error = self.load_error_short = ""
        if self.loader is not None:
            self.loader.cancel()  # the newest request wins; the older load stops within a chunk
        self.loader = SceneLoader(path)

    def cancel_load(self) -> None:
        """Stop the scene load in progress (within a chunk of it) and keep the current scene."""
        if self.loader is not None:
            self.loader.cancel()
            self.message(f"cancelled loading {self.loader.path.name}: kept the current scene", "warn")
            self.loader = None

    def open_cameras(self, path: str | Path) -> None:
        try:
            cams = load_cameras_json(path)
        except GBViewerError as exc:
            self.load_error, self.load_error_short = str(exc), ""
            self.message(str(exc), "error")
            return
        self.cameras, self.cameras_path, self.cam_index = cams, Path(path), -1
        self.message(f"{len(cams)} training cameras from {Path(path).name}")
        self.step_camera(1)

    def poll_loader(self) -> Path | None:
        """Take a finished load: the path of a newly opened scene, else None (still loading, or it failed)."""
        if self.loader is None or not self.loader.done():
            return None
        res = self.loader.poll()
        self.loader = None
        if res.cancelled:
            return None
        if res.error:
            self.load_error = res.error
            self.load_error_short = res.error.replace(str(res.path), res.path.name)
            self.message(f"could not open {res.path.name}: kept the current scene", "error")
            return None
        self.scene, self.scene_path = res.scene, res.path
        self.load_error = ""
        self.settings.recent = add_recent(self.settings.recent, res.path)
        self.cameras, self.cameras_path, self.cam_index = (res.cameras or []), res.cameras_path, -1
        if res.cameras_error:
            self.message(res.cameras_error, "error")
        for p in self.panes:
            p.forget()
        self.needs_reset = True
        self.message(f"opened {res.path.name}: {res.scene.num_splats:,} splats in {res.seconds:.2f} s"
                     + (f", {len(self.cameras)} training cameras" if self.cameras else ""))
        if self.pending_cameras is not None:
            path, self.pending_cameras = self.pending_cameras, None
            self.needs_reset = False
            self.reset_camera()
            self.open_cameras(path)
        return res.path

    # ---- camera -------------------------------------------------------------------------------------------------

    def reset_camera(self) -> None:
        if self.scene is None:
            return
        lo, hi = self.scene.robust_bounds()
        r = self.panes[0].rect
        self.controller.up = self.settings.up
        self.controller.fov_y_deg = self.settings.fov_y_deg
        self.controller.frame_bounds(lo, hi, aspect=r.w / max(1, r.h) if r.w > 1 else 4 / 3)
        self.cam_index = -1
        self.moved()

    def step_camera(self, direction: int) -> None:
        """Snap to the next (direction 1) or previous (-1) view: of the dataset's listed views when a dataset is
        open, else of the training cameras."""
        if self.dataset.dataset is not None:
            index = self.dataset.next_index(direction)
            if index is None:
                named = f" named with '{self.dataset.name_filter}'" if self.dataset.name_filter.strip() else ""
                self.message(f"no {self.dataset.split} views{named} in the dataset", "warn")
            else:
                self.snap_view(index)
            return
        if not self.cameras:
            self.message("no training cameras: open a cameras.json (or put one next to the scene)", "warn")
            return
        self.cam_index = (self.cam_index + direction) % len(self.cameras)
        self._snap(self.cameras[self.cam_index])

    def snap_view(self, index: int) -> None:
        """Snap to the dataset's view `index` (perspective, as photos are): while the camera stays, every pane
        renders the photo's camera at the rate, letterboxed to the photo's aspect (`photo_camera`)."""
        self.settings.projection = self.controller.projection = "perspective"
        self.cam_index = -1
        self._snap(self.dataset.dataset.views[index].camera)
        view = self.dataset.snapped_to(index, self.controller.state())
        self._size_panes()
        self.message(f"{view.split} view {view.name} ({view.camera.width}x{view.camera.height} photo)")

    def photo_camera(self) -> Camera | None:
        """While snapped to a dataset view: the camera every pane renders (the photo's at the rate); else None."""
        return self.dataset.camera(self.controller.state(), self.settings.rate)

    def _snap(self, cam: Camera) -> None:
        """Take `cam`'s pose and field of view, orbiting about the scene's centre."""
        if self.scene is not None:
            lo, hi = self.scene.robust_bounds()
            self.controller.centre = (np.asarray(lo, np.float64) + hi) / 2
            self.controller.radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
        self.controller.snap_to(cam)
        self.settings.fov_y_deg = self.controller.fov_y_deg
        self.moved()

    def set_up(self, up: str) -> None:
        self.settings.up = up
        self.controller.set_up(up)
        self.moved()

    def next_up(self) -> None:
        axes = list(UP_AXES)
        self.set_up(axes[(axes.index(self.settings.up) + 1) % len(axes)])

    def set_fov(self, fov_y_deg: float) -> None:
        self.controller.set_fov(fov_y_deg)
        self.settings.fov_y_deg = self.controller.fov_y_deg
        self.moved()

    def toggle_projection(self) -> None:
        """Perspective <-> orthographic; the plane through the target keeps its size on screen."""
        self.settings.projection = "orthographic" if self.settings.projection == "perspective" else "perspective"
        self.controller.projection = self.settings.projection
        self.moved()

    def toggle_fly(self) -> None:
        self.fly = not self.fly

    def fly_move(self, forward: float, right: float, upward: float, dt: float, fast: bool = False) -> None:
        """Fly mode's WASD/QE for `dt` seconds (4x faster with `fast`)."""
        if self.fly and (forward or right or upward):
            self.controller.fly(forward, right, upward, dt, self.settings.fly_speed * (4 if fast else 1))
            self.moved()

    def moved(self) -> None:
        self.last_move = time.perf_counter()

    @property
    def moving(self) -> bool:
        return time.perf_counter() - self.last_move < MOVING_HOLD_S

    # ---- rate, panes, overlays ----------------------------------------------------------------------------------

    def set_rate(self, rate: float) -> None:
        self.settings.rate = clamp_rate(rate)
        self._size_panes()

    def step_rate(self, direction: int) -> None:
        self.set_rate(step_rate(self.settings.rate, direction))

    def set_pane_count(self, n: int) -> None:
        self.settings.pane_count = min(MAX_PANES, max(1, int(n)))

    def toggle_layout(self) -> None:
        self.settings.layout = "grid" if self.settings.layout == "row" else "row"

    def set_pane(self, i: int, **changes) -> None:
        p = self.settings.panes[i]
        for k, v in changes.items():
            setattr(p, k, v)
        self.settings.panes[i] = p.normalised()

    def cycle_mode(self, i: int, direction: int = 1) -> None:
        mode = self.settings.panes[i].mode
        self.set_pane(i, mode=MODE_NAMES[(MODE_NAMES.index(mode) + direction) % len(MODE_NAMES)])

    @property
    def target(self) -> int:
        """The pane that keys act on: the one under the cursor, else the first."""
        return self.hover[0] if self.hover is not None else 0

    def next_mode(self, direction: int = 1) -> None:
        self.cycle_mode(self.target, direction)

    def toggle_split(self) -> None:
        self.set_pane(self.target, split=not self.settings.panes[self.target].split)

    def toggle_loupe(self) -> None:
        self.settings.loupe = not self.settings.loupe

    def toggle_info(self) -> None:
        self.settings.show_info = not self.settings.show_info

    def toggle_help(self) -> None:
        self.show_help = not self.show_help

    def escape(self) -> None:
        """Close the help and leave fly mode; with neither to do, cancel a scene load."""
        if not (self.show_help or self.fly):
            self.cancel_load()
        self.show_help = self.fly = False

    # ---- geometry and render requests ---------------------------------------------------------------------------

    def parts(self, i: int) -> tuple[str, ...]:
        return ("a", "b") if self.settings.panes[i].split else ("a",)

    @property
    def visible(self) -> list[PaneState]:
        return self.panes[: self.settings.pane_count]

    def layout(self, width: float, height: float, top: float, bottom: float,
               scale: tuple[float, float] = (1.0, 1.0)) -> None:
        """Place the panes in a window of width x height (minus the menu bar `top` and the status bar `bottom`)."""
        self.scale = scale
        self.viewport = v = Rect(PANEL_W, int(top), max(1, int(width) - PANEL_W), max(1, int(height - top - bottom)))
        rects = pane_rects(v.x + 4, v.y + 4, v.w - 8, v.h - 8, self.settings.pane_count, self.settings.layout)
        photo = self.photo_camera()
        for p, r in zip(self.panes, rects):
            p.rect = r if photo is None else fit_aspect(r, photo.width / photo.height)
        self._size_panes()

    def _size_panes(self) -> None:
        """Each pane's render size at the current rate (the photo's while snapped to a dataset view); also after a
        change of rate or a snap between two layouts, so that the requests of that frame say the size they have."""
        photo = self.photo_camera()
        for p in self.panes:
            p.render_size = ((photo.width, photo.height) if photo is not None else
                             render_size(round(p.rect.w * self.scale[0]), round(p.rect.h * self.scale[1]),
                                         self.settings.rate))

    def pane_at(self, x: float, y: float) -> int | None:
        return next((p.index for p in self.visible if p.rect.contains(x, y)), None)

    def pane_camera(self, i: int, preview: float = 1.0) -> Camera:
        """The camera pane i renders with at the current rate (x `preview` while moving); snapped to a dataset view,
        the photo's."""
        photo = self.photo_camera()
        if photo is not None:
            return photo if preview == 1.0 else photo.at_sampling_rate(preview)
        r = self.panes[i].rect
        base = self.controller.camera(round(r.w * self.scale[0]), round(r.h * self.scale[1]))
        return base.at_sampling_rate(self.settings.rate * preview)

    def settings_for(self, i: int, part: str) -> RenderSettings:
        """What pane i's part ('a', or 'b' of a split) renders with."""
        ps: PaneSettings = self.settings.panes[i]
        mode = Mode.parse(ps.split_mode if part == "b" else ps.mode)
        debug = "window" if ps.view == "window" and mode == Mode.GAUSSIAN_BLENDING else "none"
        return RenderSettings(mode, ps.supersample, self.settings.background, debug=debug)

    # ---- zoom video ---------------------------------------------------------------------------------------------

    def record_video(self, frames: int | None = None, out: str | Path | None = None) -> VideoJob | None:
        """Start the zoom video (x1 to x1/8) of the current view, one column per visible pane's mode, in the
        background; 480 px wide panes with the panes' aspect."""
        if self.scene is None or (self.video is not None and not self.video.finished()):
            return None
        r = self.panes[0].rect
        w = VIDEO_PANE_W
        h = max(2, round(w * r.h / max(1, r.w) / 2) * 2)
        cam = self.controller.camera(w, h)
        settings = [replace(self.settings_for(i, "a"), debug="none") for i in range(self.settings.pane_count)]
        out = Path(out) if out else shot_name(self, "zoom").with_suffix(".mp4")
        self.video = VideoJob(self.scene, cam, settings, out, frames or self.video_frames)
        self.message(f"recording {out.name} ({self.video.total} frames) in the background")
        return self.video

    def poll_video(self) -> None:
        """Say once how a finished video went."""
        v = self.video
        if v is None or not v.finished() or v.reported:
            return
        v.reported = True
        if v.error:
            self.message(f"video: {v.error}", "warn" if v.cancelled else "error")
        elif v.info is not None:
            self.message(f"saved {v.info.path} ({v.info.frames} frames, {v.info.elapsed_s:.0f} s)")
