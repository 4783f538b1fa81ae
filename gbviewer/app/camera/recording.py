"""The viewer's video (a zoom, or along its camera path), written by gbviewer.outputs.video.record_video in a thread."""

from __future__ import annotations

import threading
import time
import traceback
from pathlib import Path

from ...core.cancel import CancelToken
from ...core.errors import GBViewerError
from ...model.camera_paths import PathFrame
from ...model.scene import Scene
from ...render import RenderSettings
from ..threads.slots import lower_priority

VIDEO_CONTAINERS = {"h264": ".mp4", "h265": ".mp4", "vp9": ".webm", "av1": ".webm"}  # the Record button's codecs


class VideoJob:
    """A video along `path` (one column per mode) written by gbviewer.outputs.video.record_video in a thread, in `codec`
    (the container: `out`'s extension)."""

    def __init__(
        self,
        scene: Scene,
        path: list[PathFrame],
        settings: list[RenderSettings],
        out: Path,
        fps: float = 30.0,
        backend: str = "cpu",
        codec: str = "h264",
    ) -> None:
        from ...outputs.video import record_video

        self.out = Path(out)
        self.done_frames, self.total = 0, len(path)
        self.error = ""
        self.info = None
        self.started = time.perf_counter()
        self.reported = False  # the window said how it went
        self._cancel = CancelToken()
        self._finished = threading.Event()

        def progress(done: int, total: int) -> None:
            self.done_frames, self.total = done, total

        def run() -> None:
            lower_priority()  # the window keeps its core while the video renders
            try:
                self.info = record_video(
                    scene,
                    path,
                    settings,
                    self.out,
                    fps=fps,
                    backend=backend,
                    codec=codec,
                    progress=progress,
                    cancel=self._cancel,
                )
            except GBViewerError as exc:
                self.error = str(exc)
            except Exception as exc:  # noqa: BLE001 - shown in the window
                traceback.print_exc()
                self.error = f"{type(exc).__name__}: {exc}"
            finally:
                self._finished.set()

        self._thread = threading.Thread(target=run, name="gbviewer-video", daemon=True)
        self._thread.start()

    @property
    def fraction(self) -> float:
        return self.done_frames / max(1, self.total)

    def finished(self) -> bool:
        return self._finished.is_set()

    def cancel(self, wait: float = 0.0) -> None:
        self._cancel.set()
        if wait:
            self._thread.join(wait)

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()
