"""The camera actions of `state.AppState`: framing, snapping to training cameras and dataset views, up axis, field of
view, projection, fly mode, and whether the camera is moving."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..model.camera import UP_AXES, Camera
from ..model.scene import Scene
from .camera.control import CameraController
from .dataset import DatasetViews
from .settings import AppSettings
from .ui.layout import Rect, fit_aspect

if TYPE_CHECKING:
    from .pane_state import PaneState

MOVING_HOLD_S = 0.25  # the camera counts as moving this long after the last change


class CameraActions:
    """Mixed into `AppState`, whose attributes below it acts on."""

    settings: AppSettings
    controller: CameraController
    scene: Scene | None
    cameras: list[Camera]
    cam_index: int
    dataset: DatasetViews
    panes: list[PaneState]
    last_move: float
    pane_areas: list[Rect]
    message: Callable[..., None]  # (text, level)
    _size_panes: Callable[[], None]

    def reset_camera(self) -> None:
        """Frame the scene at the default field of view (the panel's; a snap does not change it)."""
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
        open, else of the training cameras. After the camera left a dataset view, either key snaps back to it."""
        if self.dataset.dataset is not None:
            view = self.dataset.view
            if view is not None and self.dataset.snapped(self.controller.state()) is None:
                self.snap_view(self.dataset.index)
                return
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
        cam = self.dataset.dataset.views[index].camera
        self._snap(cam)
        if self.pane_areas:  # the same scale on screen as the letterboxed photo: leaving the view does not jump
            area = self.pane_areas[0]
            box = fit_aspect(area, cam.width / cam.height)
            f = cam.fy * box.h / cam.height  # the photo's focal length in window units
            self.controller.set_fov(math.degrees(2 * math.atan(area.h / 2 / f)))
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
