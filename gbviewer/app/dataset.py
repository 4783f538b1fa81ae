"""The training dataset open beside the scene (`gbviewer SCENE --data DATASET`, or Open dataset...): loaded off the
UI thread, its views listed by split and name, the view the camera is snapped to, and the camera every pane renders
while it stays there: the photo's camera at the current rate (`eval.camera_for_rate`), so that each render and the
photo's ground truth (the analysis thread's 'photo' reference) hold the same pixels. No imgui here."""

from __future__ import annotations

import threading
import time
import traceback
from pathlib import Path
from typing import Callable

import numpy as np

from ..core.errors import GBViewerError
from ..eval import camera_for_rate
from ..io.datasets import SPLITS, Dataset, View, load_dataset
from ..io.datasets.backdrop import Backdrop, estimate_backdrop
from ..model.camera import Camera, camera_key, format_rate

Message = Callable[[str, str], None]  # (text, level): AppState.message


class DatasetLoader:
    """Loads one dataset in a thread (a COLMAP model is read by pycolmap in a child process: it may take seconds),
    and estimates the backdrop of its photos there (`background.estimate_backdrop`)."""

    def __init__(self, path: str | Path, images: str = "images", load_fn: Callable | None = None) -> None:
        self.path, self.images = Path(path).expanduser(), images
        self.started = time.perf_counter()
        self.dataset: Dataset | None = None
        self.backdrop: Backdrop | None = None
        self.error = ""
        self._load = load_fn or load_dataset
        self._done = threading.Event()
        threading.Thread(target=self._run, name="gbviewer-dataset", daemon=True).start()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def _run(self) -> None:
        try:
            self.dataset = self._load(self.path, self.images)
            self.backdrop = estimate_backdrop(self.dataset.views)
        except GBViewerError as exc:
            self.error = str(exc)
        except OSError as exc:
            self.error = f"{self.path}: {exc}"
        except Exception as exc:  # noqa: BLE001 - a loader bug is one line in the status, the viewer goes on
            traceback.print_exc()
            self.error = f"{self.path}: {type(exc).__name__}: {exc}"
        self._done.set()

    def done(self) -> bool:
        return self._done.is_set()


class DatasetViews:
    """The open dataset, the list of its views the panel shows (split and name filter), and the snapped view."""

    def __init__(self, message: Message) -> None:
        self.message = message
        self.dataset: Dataset | None = None
        self.backdrop: Backdrop | None = None  # what the open dataset's photos' borders say
        self.set_aside: tuple[Dataset, Backdrop | None] | None = None  # dropped with its scene, kept on "keep"
        self.loader: DatasetLoader | None = None
        self.error = ""  # of the last failed load (the dataset open before it stays)
        self.images = "images"  # the photo folder of a capture or a cameras.json (images_4: quarter size)
        self.split = "test"  # listed: "train", "test" or "all"
        self.name_filter = ""  # listed: names containing it (any case)
        self.index = -1  # into dataset.views: the view last snapped to
        self.snap_key: tuple | None = None  # the controller's state right after that snap
        self.snaps = 0  # counts snaps (the analysis turns to the photo reference on each)

    # ---- opening ------------------------------------------------------------------------------------------------

    def open(self, path: str | Path, images: str | None = None) -> None:
        """Load the dataset at `path` off the UI thread (photos in the folder `images`, by default the last one
        given, for a capture or a cameras.json); `poll` takes it in."""
        self.error = ""
        self.images = images or self.images or "images"
        self.loader = DatasetLoader(path, self.images)

    def poll(self) -> Dataset | None:
        """Take a finished load: the new dataset (said in the status bar), else None (loading, or it failed: one
        line in the status bar, the open dataset and the scene stay)."""
        if self.loader is None or not self.loader.done():
            return None
        ld, self.loader = self.loader, None
        if ld.dataset is None:
            self.error = ld.error
            self.message(f"dataset not opened: {ld.error}", "error")
            return None
        self.dataset, self.backdrop, self.index, self.snap_key = ld.dataset, ld.backdrop, -1, None
        self.set_aside = None
        test = sum(v.in_split("test") for v in ld.dataset.views)
        self.message(
            f"dataset {ld.path.name}: {len(ld.dataset.views)} views ({test} test, {ld.dataset.format}) in "
            f"{ld.elapsed:.1f} s; [ ] step through the {self.split} views",
            "info",
        )
        return ld.dataset

    def close(self) -> Dataset | None:
        """Drop the open dataset (and the snapped view); the dataset that was open, or None."""
        d, self.dataset, self.backdrop, self.index, self.snap_key = self.dataset, None, None, -1, None
        self.set_aside = None
        return d

    def drop_for_new_scene(self, fits: bool) -> None:
        """Another scene opened: the dataset goes; kept aside for `keep` when the scene's bounds `fit` its
        cameras (said in the status bar either way)."""
        d, b = self.dataset, self.backdrop
        if d is None:
            return
        self.close()
        if fits:
            self.set_aside = (d, b)
            self.message(
                f"closed dataset {d.root.name} with the previous scene; the new scene fits its cameras: "
                "'Keep dataset' in the panel reopens it",
                "warn",
            )
        else:
            self.message(f"closed dataset {d.root.name}: it belongs to the previous scene", "info")

    def keep(self) -> None:
        """Reopen the dataset the last scene change set aside."""
        if self.set_aside is not None:
            (self.dataset, self.backdrop), self.set_aside = self.set_aside, None
            self.index, self.snap_key = -1, None

    # ---- the list and the snapped view --------------------------------------------------------------------------

    def listed(self) -> list[int]:
        """Indices into dataset.views of the views in the list: of the chosen split, named with the filter."""
        if self.dataset is None:
            return []
        f = self.name_filter.strip().lower()
        return [k for k, v in enumerate(self.dataset.views) if v.in_split(self.split) and f in v.name.lower()]

    def set_split(self, split: str) -> None:
        if split not in SPLITS:
            raise ValueError(f"split {split!r}; expected one of {', '.join(SPLITS)}")
        self.split = split

    def next_index(self, direction: int) -> int | None:
        """The listed view after (direction 1) or before (-1) the snapped one, wrapping around; the first (or last)
        listed one when the snapped view is not listed; None when none is."""
        listed = self.listed()
        if not listed:
            return None
        if self.index in listed:
            return listed[(listed.index(self.index) + direction) % len(listed)]
        return listed[0 if direction > 0 else -1]

    def snapped_to(self, index: int, key: tuple) -> View:
        """Record the snap to view `index`, the controller then in state `key`."""
        self.index, self.snap_key = index, key
        self.snaps += 1
        return self.dataset.views[index]

    @property
    def view(self) -> View | None:
        """The view last snapped to (the camera may have left it since)."""
        return self.dataset.views[self.index] if self.dataset is not None and self.index >= 0 else None

    def snapped(self, key: tuple) -> View | None:
        """The snapped view while the controller is still in the state it was snapped to (`key`: its state now)."""
        return self.view if self.snap_key is not None and key == self.snap_key else None

    def camera(self, key: tuple, rate: float) -> Camera | None:
        """While snapped (`key`: the controller's state now): the camera every pane renders, the photo's at `rate`
        (`camera_for_rate`: the ground truth's pixels); at rates without a photo (x2, x1/3), the photo's camera at
        that rate. None when not snapped."""
        view = self.snapped(key)
        if view is None:
            return None
        try:
            return camera_for_rate(view.camera, rate)
        except GBViewerError:
            return view.camera.at_sampling_rate(rate)

    def photo_for(self, camera: Camera, rate: float) -> tuple[View | None, str]:
        """The view whose photo at `rate` has the pixels of a render at `camera` (the snapped one, rendered as
        `camera` says), or None and why not, in a few words."""
        view = self.view
        if self.dataset is None:
            return None, "open a dataset (--data, or Open dataset... in the panel)"
        if view is None:
            return None, "snap to a dataset view ([ ] or the Dataset list)"
        try:
            want = camera_for_rate(view.camera, rate)
        except GBViewerError:
            return None, f"no photo at {format_rate(rate)} (only x1/k, k up to the photo's size)"
        if camera_key(want) != camera_key(camera):
            return None, f"the camera left {view.name} ([ ] to snap back)"
        return view, ""


def bounds_fit_cameras(lo: np.ndarray, hi: np.ndarray, cameras: list[Camera]) -> bool:
    """Whether a scene with robust bounds [lo, hi] is plausibly the one the cameras photographed: its centre lies
    in front of at least half of them and inside their images (a camera over a hundred times the scene's size
    away from its centre does not count: another scene's units or place)."""
    if not cameras:
        return False
    centre = (np.asarray(lo, np.float64) + np.asarray(hi, np.float64)) / 2
    size = max(float(np.linalg.norm(np.asarray(hi, np.float64) - lo)), 1e-9)
    seen = 0
    for c in cameras:
        x = c.R.astype(np.float64) @ centre + c.t
        if x[2] <= 0 or np.linalg.norm(c.position - centre) > 100 * size:
            continue
        u, v = c.fx * x[0] / x[2] + c.cx, c.fy * x[1] / x[2] + c.cy
        seen += 0 <= u <= c.width and 0 <= v <= c.height
    return 2 * seen >= len(cameras)
