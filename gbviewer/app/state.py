"""The viewer's state and the actions that the panel, the menus and the keys trigger. No imgui, glfw or OpenGL here:
all of it is unit-tested without a window (tests/app/test_state.py); `window.ViewerApp` draws it."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Literal

from ..core.errors import GBViewerError
from ..io.datasets.backdrop import RGB, choose_background, format_rgb
from ..io.trained_as import describe
from ..model.camera import Camera, load_cameras_json
from ..model.camera_paths import zoom_path
from ..model.scene import Scene
from ..render import Mode, RenderSettings
from ..render.presets import trained_spec
from .background import FIXED, PHOTOS
from .camera.control import CameraController
from .camera.path_keys import PathKeys, is_nerfstudio_file
from .camera.recording import VIDEO_CONTAINERS, VideoJob
from .camera_actions import CameraActions
from .dataset import DatasetViews, bounds_fit_cameras
from .frames.rates import clamp_rate, first_preview_lod, render_size, step_rate
from .pane_state import PaneState
from .screenshots import shot_name
from .settings import MAX_PANES, MODE_NAMES, AppSettings, PaneSettings, add_recent
from .threads import loading
from .ui.layout import PANEL_W, Rect, dock_split, fit_aspect, pane_rects

VIDEO_PANE_W = 480
Level = Literal["info", "warn", "error"]  # of a status-bar message


def is_cameras_file(path: str | Path) -> bool:
    """A file the viewer opens as training cameras rather than a scene."""
    return Path(path).suffix.lower() == ".json"


class AppState(CameraActions):
    """Scene, cameras, panes and their settings, and the actions on them (the camera's in `CameraActions`)."""

    def __init__(self, settings: AppSettings, cameras: str | Path | None = None, background: RGB | None = None) -> None:
        self.settings = settings
        if background is not None:
            settings.background = tuple(background)
        self.background_source = FIXED  # or PHOTOS: the open dataset's backdrop (`background`)
        self.background_given = background is not None  # on the command line: a dataset's photos do not override it
        self.controller = CameraController(fov_y_deg=settings.fov_y_deg, up=settings.up, projection=settings.projection)
        self.scene: Scene | None = None
        self.scene_path: Path | None = None
        self.cameras: list[Camera] = []
        self.cameras_path: Path | None = None
        self.cam_index = -1
        self.dataset = DatasetViews(self.message)  # the training photos, their views, the snapped one
        self.loader: loading.SceneLoader | None = None
        self.lod_due: float | None = None  # perf_counter time by which the scene's hierarchy build begins at the
        # latest (PaneRenders.poll begins it sooner, once every pane shows the scene); None once begun, or for none
        self.load_error = self.load_error_short = ""
        self.fly = False
        self.show_help = False
        self.last_move = 0.0
        self.messages: list[tuple[float, str, Level]] = []  # (time, text, level)
        self.panes = [PaneState(i) for i in range(MAX_PANES)]
        self.dock_rect: Rect | None = None  # the docked inspector's area (layout)
        self.pane_areas: list[Rect] = []  # each pane's rect before letterboxing to a snapped photo
        self.viewport = Rect(PANEL_W, 0, 1, 1)
        self.scale = (1.0, 1.0)  # framebuffer pixels per window coordinate
        self.hover: tuple[int, float, float] | None = None  # pane, u, v under the cursor
        self.dragging_split: int | None = None
        self.needs_reset = False  # frame the camera once the panes have their size
        self.pending_cameras = cameras  # opened once the first scene is in
        self.video: VideoJob | None = None
        self.video_frames = 90
        self.video_codec = "h264"
        self.path_keys = PathKeys()  # the camera path the Record button follows once it has two keys

    def message(self, text: str, level: Level = "info") -> None:
        self.messages.append((time.perf_counter(), text, level))
        self.messages = self.messages[-6:]

    # ---- opening ------------------------------------------------------------------------------------------------

    def open(self, path: str | Path) -> None:
        """Open a scene (in the background) or, for a .json, training cameras."""
        path = Path(path).expanduser()
        if is_nerfstudio_file(path):
            self.import_camera_path(path)
            return
        if is_cameras_file(path):
            self.open_cameras(path)
            return
        self.load_error = self.load_error_short = ""
        if self.loader is not None:
            self.loader.cancel()  # the newest request wins; the older load stops within a chunk
        self.loader = loading.SceneLoader(path)

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
        if self.scene is not None:  # another scene: the dataset of the previous one goes (kept aside if it fits)
            lo, hi = res.scene.robust_bounds()
            ds = self.dataset.dataset
            self.dataset.drop_for_new_scene(ds is not None and bounds_fit_cameras(lo, hi, [v.camera for v in ds.views]))
            self.background_source = FIXED
        self.scene, self.scene_path = res.scene, res.path
        self.lod_due = time.perf_counter() + loading.FIRST_PICTURES_WAIT_S if res.scene.oit is None else None
        self.load_error = ""
        self.settings.recent = add_recent(self.settings.recent, res.path)
        self.cameras, self.cameras_path, self.cam_index = (res.cameras or []), res.cameras_path, -1
        if res.cameras_error:
            self.message(res.cameras_error, "error")
        for p in self.panes:
            p.forget(first_preview_lod(res.scene.num_splats))
        trained = trained_spec(res.scene.meta)
        if trained is not None:  # pane A, the reference of the differences, shows the scene as it was trained
            self.settings.panes[0].mode = trained
        self.needs_reset = True
        self.message(
            f"opened {res.path.name}: {res.scene.num_splats:,} splats in {res.seconds:.2f} s"
            + (f", {len(self.cameras)} training cameras" if self.cameras else "")
            + (f"; pane A {trained}, as trained ({describe(res.scene.meta)})" if trained else "")
        )
        if self.pending_cameras is not None:
            path, self.pending_cameras = self.pending_cameras, None
            self.needs_reset = False
            self.reset_camera()
            self.open_cameras(path)
        return res.path

    # ---- the dataset and the background -------------------------------------------------------------------------

    def poll_dataset(self) -> None:
        """Take a finished dataset load; its photos' backdrop becomes the background when they are opaque (unless
        the command line gave one)."""
        if self.dataset.poll() is not None:
            given = tuple(self.settings.background) if self.background_given else None
            choice = choose_background(given, self.dataset.backdrop)
            if choice.source == PHOTOS:
                self.background_source = PHOTOS
                self.message(f"background from the photos: {choice.describe()}")

    def close_dataset(self) -> None:
        d = self.dataset.close()
        self.background_source = FIXED
        if d is not None:
            self.message(f"closed dataset {d.root.name}")
        self._size_panes()

    def keep_dataset(self) -> None:
        """Reopen the dataset set aside by the last scene change (the new scene fits its cameras)."""
        self.dataset.keep()
        if self.dataset.dataset is not None:
            self.message(f"kept dataset {self.dataset.dataset.root.name} for {self.scene_path.name}")

    @property
    def background(self) -> RGB:
        """The colour the panes render on: the photos' backdrop (source PHOTOS, a dataset open), else the user's."""
        b = self.dataset.backdrop
        if self.background_source == PHOTOS and b is not None:
            return b.colour
        return tuple(self.settings.background)

    def set_background(self, rgb: RGB) -> None:
        """A fixed colour (saved in the settings)."""
        self.settings.background = tuple(min(1.0, max(0.0, float(c))) for c in rgb)
        self.background_source = FIXED

    def use_photo_background(self) -> None:
        if self.dataset.backdrop is not None:
            self.background_source = PHOTOS

    def background_note(self) -> str:
        """The background in a few words: 'bg 0.80 0.80 0.80 (photos)'."""
        src = " (photos)" if self.background_source == PHOTOS and self.dataset.backdrop is not None else ""
        return f"bg {format_rgb(self.background)}{src}"

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

    def layout(
        self,
        width: float,
        height: float,
        top: float,
        bottom: float,
        scale: tuple[float, float] = (1.0, 1.0),
        dock: str | None = None,
    ) -> None:
        """Place the panes in a window of width x height (minus the menu bar `top` and the status bar `bottom`),
        beside the docked inspector (`dock`: 'below', 'right' or None; its area: `dock_rect`)."""
        self.scale = scale
        self.viewport = Rect(PANEL_W, int(top), max(1, int(width) - PANEL_W), max(1, int(height - top - bottom)))
        v, self.dock_rect = dock_split(self.viewport, dock)
        rects = pane_rects(v.x + 4, v.y + 4, v.w - 8, v.h - 8, self.settings.pane_count, self.settings.layout)
        self.pane_areas = rects
        photo = self.photo_camera()
        for p, r in zip(self.panes, rects):
            p.rect = r if photo is None else fit_aspect(r, photo.width / photo.height)
        self._size_panes()

    def _size_panes(self) -> None:
        """Each pane's render size at the current rate (the photo's while snapped to a dataset view); also after a
        change of rate or a snap between two layouts, so that the requests of that frame say the size they have."""
        photo = self.photo_camera()
        for p in self.panes:
            p.render_size = (
                (photo.width, photo.height)
                if photo is not None
                else render_size(round(p.rect.w * self.scale[0]), round(p.rect.h * self.scale[1]), self.settings.rate)
            )

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
        spec = ps.split_mode if part == "b" else ps.mode
        settings = RenderSettings.parse(  # interactive frames: fast unless the pane asks for exact
            spec,
            default_precision="fast",
            supersample=ps.supersample,
            background=self.background,
            lod=ps.lod if ps.lod > 0 else None,
        )
        debug = "window" if ps.view == "window" and settings.mode == Mode.GAUSSIAN_BLENDING else "none"
        return replace(settings, debug=debug)

    # ---- zoom video ---------------------------------------------------------------------------------------------

    def video_camera(self) -> Camera:
        """The current view at the video's pane size: VIDEO_PANE_W wide, the panes' aspect, even height."""
        r = self.panes[0].rect
        h = max(2, round(VIDEO_PANE_W * r.h / max(1, r.w) / 2) * 2)
        return self.controller.camera(VIDEO_PANE_W, h)

    def record_video(self, frames: int | None = None, out: str | Path | None = None) -> VideoJob | None:
        """Start the video, one column per visible pane's mode, in the background, in `video_codec`: along the
        camera path once it has two keys (an imported one at its frame rate), else the zoom (x1 to x1/8) of the
        current view; VIDEO_PANE_W px wide panes."""
        if self.scene is None or (self.video is not None and not self.video.finished()):
            return None
        settings = [replace(self.settings_for(i, "a"), debug="none") for i in range(self.settings.pane_count)]
        along = len(self.path_keys) >= 2
        out = Path(out) if out else shot_name(self, "path" if along else "zoom", VIDEO_CONTAINERS[self.video_codec])
        try:
            path = (
                self.path_keys.frames(VIDEO_PANE_W)
                if along
                else zoom_path(self.video_camera(), frames or self.video_frames)
            )
        except GBViewerError as exc:
            self.message(f"video: {exc}", "error")
            return None
        fps = self.path_keys.frame_rate if along else 30.0
        self.video = VideoJob(self.scene, path, settings, out, fps=fps, codec=self.video_codec)
        self.message(f"recording {out.name} ({self.video.total} frames) in the background")
        return self.video

    def add_keyframe(self) -> None:
        """A keyframe of the camera path at the current view."""
        self.path_keys.add(self.video_camera())
        self.message(f"camera path: {len(self.path_keys)} keyframes")

    def import_camera_path(self, path: str | Path) -> None:
        """Take nerfstudio's camera_path.json as the camera path; the view snaps to its first camera."""
        try:
            p = self.path_keys.import_file(path)
        except GBViewerError as exc:
            self.message(str(exc), "error")
            return
        first = p.frames[0] if p.frames else p.keys[0].camera
        self._snap(first)
        self.message(
            f"camera path {Path(path).name}: {len(p.keys)} keyframes, {len(p.frames)} frames "
            f"({p.size[0]}x{p.size[1]}, {p.frame_rate:g} fps)"
        )

    def export_camera_path(self, out: str | Path | None = None) -> Path | None:
        """Write the camera path as nerfstudio's camera_path.json (into the screenshot folder by default)."""
        try:
            written = self.path_keys.export(Path(out) if out else shot_name(self, "camera_path", ".json"))
        except GBViewerError as exc:
            self.message(f"camera path: {exc}", "error")
            return None
        self.message(f"saved {written.name} (nerfstudio camera_path.json)")
        return written

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
