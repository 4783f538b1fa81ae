"""Cancelling a render and following its progress: `gb.render(..., cancel=token, on_progress=fn, partial=array)`.

A `RenderControl` wraps one render's `cancel` (a gbviewer.CancelToken, whose flag the native CPU loop reads directly,
or a threading.Event, copied into a flag of the render's own by `report`), its `on_progress(done, total)` and its
`partial` frame. Progress is reported from the render's own thread: the native CPU module calls `report` between
tiles (at most every 5 ms) and at the end; GPU backends call `step` between their dispatches. A callback that raises
ends the render with one CallbackError (the render cancelled, the callback's exception chained as its cause).
`partial`, a float32 (height, width, 3) array, receives the frame's pixels as they are made: tile by tile on the CPU
backend (centre out), in one go at the end of a GPU frame.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from ..core.cancel import Cancellable, CancelToken, cancel_problem
from ..core.errors import CallbackError, RenderCancelled, RenderError

Progress = Callable[[int, int], None]


class RenderControl:
    """One render's cancel flag, progress and partial frame; `check()` raises RenderCancelled once cancelled."""

    def __init__(
        self,
        cancel: Cancellable | None = None,
        on_progress: Callable[..., None] | None = None,
        partial: np.ndarray | None = None,
    ) -> None:
        if why := cancel_problem(cancel):
            raise RenderError(why)
        self.cancel, self.on_progress, self.partial = cancel, on_progress, partial
        token = isinstance(cancel, CancelToken)
        self.flag = cancel.flag if token else np.zeros(1, np.int64)  # what the native loop reads
        self._bridged = cancel is not None and not token  # an Event: copied into self.flag by report()

    @property
    def hook(self) -> Callable[..., None] | None:
        """The native render's on_progress: `report` where there is a callback or an Event to forward, else None."""
        return self.report if self.on_progress is not None or self._bridged else None

    def __enter__(self) -> RenderControl:
        self.check()
        return self

    def __exit__(self, *exc) -> None:
        return None

    def report(self, *counts: int) -> None:
        """Progress from the render's thread, (done, total) or render_many's (job, done, total): the caller's
        on_progress (an exception it raises becomes a CallbackError, which stops the render), then an Event's state
        copied into the flag."""
        if self.on_progress is not None:
            try:
                self.on_progress(*counts)
            except Exception as exc:
                raise CallbackError(
                    f"on_progress raised {type(exc).__name__}: {exc}; the render was cancelled"
                ) from exc
        self._forward()

    def _forward(self) -> None:
        if self._bridged and self.cancel.is_set():
            self.flag[0] = 1

    def step(self, done: int, total: int) -> None:
        """For backends without the native loop (GPU dispatches): report progress, then `check()`."""
        self.report(done, total)
        self.check()

    def check_partial(self, width: int, height: int) -> None:
        """Refuse a partial frame buffer the render cannot write (before any work)."""
        p = self.partial
        if p is not None and not (
            isinstance(p, np.ndarray)
            and p.dtype == np.float32
            and p.shape == (height, width, 3)
            and p.flags.c_contiguous
            and p.flags.writeable
        ):
            got = f"{p.dtype} {p.shape}" if isinstance(p, np.ndarray) else type(p).__name__
            raise RenderError(
                f"partial: expected a writable C-contiguous float32 array of shape ({height}, {width}, 3), got {got}"
            )

    def fill_partial(self, image: np.ndarray) -> None:
        """GPU backends: the whole frame at once."""
        if self.partial is not None:
            self.partial[...] = image

    def check(self, seen: bool = False) -> None:
        """Raise RenderCancelled if the render's cancel is set, or `seen` (a native frame that saw the flag set and
        stopped early: its image is incomplete even where the caller has cleared the token since)."""
        self._forward()
        if self.flag[0] or seen:
            raise RenderCancelled("render cancelled")


class FrameLock:
    """The lock one renderer's frames run under. A frame started on the thread that holds it (an on_progress that
    renders with the same renderer) would wait for itself forever: it raises a RenderError instead."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._owner: int | None = None

    def __enter__(self) -> FrameLock:
        if self._owner == threading.get_ident():
            raise RenderError(
                "a frame was started from inside a frame of the same renderer (its on_progress?): "
                "render there with a renderer of its own (gbviewer.render.create_renderer)"
            )
        self._lock.acquire()
        self._owner = threading.get_ident()
        return self

    def __exit__(self, *exc) -> None:
        self._owner = None
        self._lock.release()
