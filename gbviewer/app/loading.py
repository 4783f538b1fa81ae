"""Scene loading off the UI thread (and the training cameras of a cameras.json beside the scene)."""

from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..camera import Camera, load_cameras_json
from ..errors import GBViewerError
from ..scene import Scene


@dataclass
class LoadResult:
    path: Path
    scene: Scene | None = None
    cameras: list[Camera] | None = None
    cameras_path: Path | None = None
    cameras_error: str = ""
    error: str = ""
    seconds: float = 0.0


class SceneLoader:
    """Loads one scene (and a cameras.json beside it) in a thread; `poll()` returns the result once."""

    def __init__(self, path: str | Path, load_fn: Any = None) -> None:
        from ..io import load

        self.path = Path(path).expanduser()
        self.started = time.perf_counter()
        try:
            self.size = self.path.stat().st_size if self.path.is_file() else 0
        except OSError:
            self.size = 0
        self._load = load_fn or load
        self._result: LoadResult | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gbviewer-load", daemon=True)
        self._thread.start()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def _run(self) -> None:
        res = LoadResult(self.path)
        try:
            res.scene = self._load(self.path)
            side = self.path.parent / "cameras.json" if not self.path.is_dir() else self.path / "cameras.json"
            if side.is_file():
                res.cameras_path = side
                try:
                    res.cameras = load_cameras_json(side)
                except GBViewerError as exc:
                    res.cameras_error = str(exc)
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
