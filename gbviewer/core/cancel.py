"""One cancel token for renders, loads and videos: `token = gb.CancelToken()`, pass it as `cancel=token`, and
`token.set()` stops that work (the call raises a `gbviewer.core.errors.Cancelled`).

The token owns the flag word the native CPU renderer reads: `set()` writes it and every worker thread of a running
render sees it before its next tile, with no helper thread in between. It has threading.Event's `set`, `is_set`,
`wait` and `clear`, so code written for an Event takes a token, and every `cancel=` also takes a plain
threading.Event (or anything with `is_set()`): a render then checks it from its own thread between tiles, at most
every few milliseconds (the report that drives `on_progress`), and copies it into a flag of its own.
"""

from __future__ import annotations

import threading
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Cancellable(Protocol):
    """What every `cancel=` takes: a CancelToken, a threading.Event, or anything with is_set()."""

    def is_set(self) -> bool: ...


def cancel_problem(cancel: object) -> str | None:
    """None where `cancel` is None or Cancellable (with a callable is_set), else the one-line reason, naming
    `cancel` (the caller raises its own error with it)."""
    if cancel is None or (isinstance(cancel, Cancellable) and callable(cancel.is_set)):
        return None
    return (
        f"cancel: expected a gbviewer.CancelToken, a threading.Event or an object with an is_set() method (or "
        f"None), got {type(cancel).__name__}"
    )


class CancelToken:
    """A cancel flag shared with the native renderer (see the module docstring); threading.Event's interface."""

    __slots__ = ("_flag", "_event")

    def __init__(self) -> None:
        self._flag = np.zeros(1, np.int64)
        self._event = threading.Event()

    @property
    def flag(self) -> np.ndarray:
        """The int64[1] word the native render loop reads (nonzero: cancelled)."""
        return self._flag

    def set(self) -> None:
        self._flag[0] = 1
        self._event.set()

    def is_set(self) -> bool:
        return bool(self._flag[0])

    def wait(self, timeout: float | None = None) -> bool:
        """Block until set (or `timeout` seconds); True once set."""
        return self._event.wait(timeout)

    def clear(self) -> None:
        self._flag[0] = 0
        self._event.clear()

    def __repr__(self) -> str:
        return f"CancelToken(set={self.is_set()})"
