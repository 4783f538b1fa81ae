"""Cancelling a render and following its progress: `gb.render(..., cancel=event, on_progress=fn, partial=array)`.

A `RenderControl` holds the int64[3] block the native CPU module polls between tiles ([0] cancel flag, [1] tiles
blended, [2] tiles in the frame) and, while a render runs, a thread that copies the caller's `threading.Event`
into it and calls `on_progress(done, total)`; GPU backends check it between their dispatches instead. `partial`, a
float32 (height, width, 3) array, receives the frame's pixels as they are made: tile by tile on the CPU backend
(centre out), in one go at the end of a GPU frame.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from ..errors import RenderCancelled, RenderError

POLL_S = 0.005  # how often the event is forwarded and progress reported
Progress = Callable[[int, int], None]


class RenderControl:
    """Context manager around one render; `check()` raises RenderCancelled once the event is set."""

    def __init__(self, cancel: threading.Event | None = None, on_progress: Progress | None = None,
                 partial: np.ndarray | None = None) -> None:
        self.cancel, self.on_progress, self.partial = cancel, on_progress, partial
        self.block = np.zeros(3, np.int64)
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def active(self) -> bool:
        return self.cancel is not None or self.on_progress is not None

    def __enter__(self) -> RenderControl:
        self.check()
        if self.active:
            self._thread = threading.Thread(target=self._watch, name="gbviewer-render-control", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, kind, *exc) -> None:
        self._done.set()
        if self._thread is not None:
            self._thread.join()
        if kind is None and self.on_progress is not None and self.block[2]:
            self.on_progress(int(self.block[1]), int(self.block[2]))  # the last count, in the render's thread

    def _forward(self) -> None:
        if self.cancel is not None and self.cancel.is_set():
            self.block[0] = 1

    def _watch(self) -> None:
        while not self._done.wait(POLL_S):
            self._forward()
            if self.on_progress is not None and self.block[2]:
                self.on_progress(int(self.block[1]), int(self.block[2]))

    def step(self, done: int, total: int) -> None:
        """For backends without the native block (GPU dispatches): record progress, then `check()`."""
        self.block[1], self.block[2] = done, total
        self.check()

    def check_partial(self, width: int, height: int) -> None:
        """Refuse a partial frame buffer the render cannot write (before any work)."""
        p = self.partial
        if p is not None and not (isinstance(p, np.ndarray) and p.dtype == np.float32 and p.shape == (height, width, 3)
                                  and p.flags.c_contiguous and p.flags.writeable):
            got = f"{p.dtype} {p.shape}" if isinstance(p, np.ndarray) else type(p).__name__
            raise RenderError(f"partial: expected a writable C-contiguous float32 array of shape ({height}, {width}, 3),"
                              f" got {got}")

    def fill_partial(self, image: np.ndarray) -> None:
        """GPU backends: the whole frame at once."""
        if self.partial is not None:
            self.partial[...] = image

    def check(self) -> None:
        """Raise RenderCancelled if the caller's event is set."""
        self._forward()
        if self.block[0]:
            raise RenderCancelled("render cancelled")
