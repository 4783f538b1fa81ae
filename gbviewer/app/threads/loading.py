"""Scene loading off the UI thread (and the training cameras of a cameras.json beside the scene), with the load's
progress for a determinate bar, and cancellation; then the scene's level-of-detail hierarchy, for the previews, in
the background."""

from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...core.cancel import CancelToken
from ...core.errors import GBViewerError, LoadCancelled
from ...lod import hierarchy_for
from ...model.camera import Camera, load_cameras_json
from ...model.scene import Scene
from .slots import lower_priority

LOD_NICE = 19  # the hierarchy's build runs at the lowest priority: below the render thread, whose frames of the
# scene it must not delay (nice 10 against 0 would leave the render a tenth of the cores it shares with it)
FIRST_PICTURES_WAIT_S = 10.0  # the longest a scene's hierarchy build waits for the panes' first pictures of it


def start_lod(scene: Scene) -> None:
    """Build (or read from the cache) the scene's hierarchy for the previews' cuts in a background thread at the
    lowest priority (the previews draw the scene's sparse stand-in until it is there). The viewer starts it once its
    panes show their first pictures of the scene (neither the build nor the read, which holds the GIL in stretches,
    competes with them), or FIRST_PICTURES_WAIT_S after the scene opened; a scene replaced (or a viewer closed)
    before then starts none."""
    threading.Thread(target=prepare_lod, args=(scene,), name="gbviewer-lod", daemon=True).start()


def prepare_lod(scene: Scene) -> None:
    """The body of `start_lod`'s thread. A failure is left to the first render of a cut to report."""
    lower_priority(LOD_NICE)  # this thread's, and the build's OpenMP threads' it starts
    try:
        hierarchy_for(scene)
    except (GBViewerError, OSError, MemoryError):
        pass


@dataclass(eq=False)
class LoadResult:
    path: Path
    scene: Scene | None = None
    cameras: list[Camera] | None = None
    cameras_path: Path | None = None
    cameras_error: str = ""
    error: str = ""
    seconds: float = 0.0
    cancelled: bool = False  # stopped by `SceneLoader.cancel()`: no scene, no error


class SceneLoader:
    """Loads one scene (and a cameras.json beside it) in a thread; `poll()` returns the result once. `progress`
    is the load's latest (done, total, unit) report (None before the first), `cancel()` stops it within a chunk."""

    def __init__(self, path: str | Path, load_fn: Any = None) -> None:
        from ...io import load

        self.path = Path(path).expanduser()
        self.started = time.perf_counter()
        self._load = load_fn or load
        self.progress: tuple[int, int, str] | None = None
        self._first: dict[str, tuple[float, int]] = {}  # unit -> (time, done) of its first report: the rate
        self._cancel = CancelToken()
        self._result: LoadResult | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gbviewer-load", daemon=True)
        self._thread.start()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def _report(self, done: int, total: int, unit: str) -> None:
        self._first.setdefault(unit, (time.perf_counter(), done))
        self.progress = (done, total, unit)

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def fraction(self) -> float | None:
        """How far the current phase (reading, then decoding) is, 0..1; None before the load reports."""
        p = self.progress
        return None if p is None or p[1] <= 0 else min(1.0, p[0] / p[1])

    def describe(self) -> str:
        """'reading 40% (12.3 / 30.1 MB, 85 MB/s)', 'decoding 40% (1,200,000 / 3,000,000 splats)' or 'opening'."""
        p = self.progress  # one report: the load thread replaces it
        if p is None or p[1] <= 0:
            return "opening"
        done, total, unit = p
        pct = f"{100 * min(1.0, done / total):.0f}%"
        if unit != "bytes":
            return f"decoding {pct} ({done:,} / {total:,} {unit})"
        t0, done0 = self._first[unit]
        dt = time.perf_counter() - t0
        rate = f", {(done - done0) / dt / 1e6:.0f} MB/s" if dt > 0.2 and done > done0 else ""
        return f"reading {pct} ({done / 1e6:.1f} / {total / 1e6:.1f} MB{rate})"

    def _run(self) -> None:
        res = LoadResult(self.path)
        try:
            res.scene = self._load(self.path, progress=self._report, cancel=self._cancel)
            side = self.path.parent / "cameras.json" if not self.path.is_dir() else self.path / "cameras.json"
            if side.is_file():
                res.cameras_path = side
                try:
                    res.cameras = load_cameras_json(side)
                except GBViewerError as exc:
                    res.cameras_error = str(exc)
        except LoadCancelled:
            res.cancelled = True
        except GBViewerError as exc:
            res.error = str(exc)
        except (OSError, MemoryError) as exc:
            res.error = f"{self.path}: {exc}"
        except Exception as exc:  # noqa: BLE001 - a loader bug is shown, the viewer keeps the previous scene
            traceback.print_exc()
            res.error = f"{self.path}: {type(exc).__name__}: {exc}"
        res.seconds = self.elapsed
        self._result = res
        self._done.set()

    def done(self) -> bool:
        return self._done.is_set()

    def poll(self) -> LoadResult | None:
        return self._result if self._done.is_set() else None
