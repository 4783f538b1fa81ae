"""Progress and cancellation of a scene load: `gb.load(path, progress=fn, cancel=event)`.

A load goes through up to two phases, each with its unit: "bytes" (the file read from disk, and inflated where the
format is one compressed stream) and then "splats" (decoded into the Scene's arrays). `fn(done, total, unit)` is
called at the start of a phase (done 0), after each chunk, and at its end (done == total): done never decreases
within a unit, and a phase reports at most REPORTS + 2 times. Chunks are at least MIN_BYTES / MIN_SPLATS long, so a
small file is one chunk. Once `cancel` (a gbviewer.CancelToken, a threading.Event or anything with is_set()) is
set, the load raises LoadCancelled at the next chunk. An exception `fn` raises ends the load with a CallbackError
(chained to it), never blamed on the file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..cancel import Cancellable, cancel_problem
from ..errors import CallbackError, InvalidValue, LoadCancelled

Progress = Callable[[int, int, str], None]
REPORTS = 100  # chunks per phase at most
MIN_BYTES = 1 << 20  # smallest chunk of a read
MIN_SPLATS = 1 << 16  # smallest chunk of a decode


class LoadProgress:
    """Reports a load's phases to the caller's `fn` and raises LoadCancelled once `cancel` is set."""

    def __init__(self, fn: Progress | None = None, cancel: Cancellable | None = None) -> None:
        if why := cancel_problem(cancel):
            raise InvalidValue(why)
        self.fn, self.cancel = fn, cancel
        self._last: dict[str, int] = {}

    def check(self) -> None:
        """Raise LoadCancelled if the caller's event is set."""
        if self.cancel is not None and self.cancel.is_set():
            raise LoadCancelled("load cancelled")

    def report(self, done: int, total: int, unit: str) -> None:
        """Tell the caller (skipping steps under 1/REPORTS of `total` and any step back), then check `cancel`."""
        last = self._last.get(unit, -1)
        if self.fn is not None and done > last and (done in (0, total) or done - last >= -(-total // REPORTS)):
            self._last[unit] = done
            try:
                self.fn(done, total, unit)
            except Exception as exc:
                raise CallbackError(f"progress raised {type(exc).__name__}: {exc}; the load was cancelled") from exc
        self.check()

    def chunks(self, total: int, unit: str, minimum: int) -> Iterator[tuple[int, int]]:
        """(begin, end) ranges covering 0..total, each reported as done once the caller has handled it."""
        self.report(0, total, unit)
        for begin, end in _ranges(total, minimum):
            yield begin, end
            self.report(end, total, unit)

    def read(self, fh, size: int) -> bytearray:
        """Up to `size` bytes of the binary file `fh`, read in chunks and reported as bytes."""
        out = bytearray(size)
        view = memoryview(out)
        got = 0
        for begin, end in self.chunks(size, "bytes", MIN_BYTES):
            n = fh.readinto(view[begin:end])
            got += n
            if n < end - begin:
                break
        view.release()
        del out[got:]
        self.report(size, size, "bytes")
        return out

    def pieces(self, fh, size: int) -> Iterator[bytes]:
        """The `size` bytes of the binary file `fh` in chunks, each reported as bytes once the caller took it."""
        for begin, end in self.chunks(size, "bytes", MIN_BYTES):
            yield fh.read(end - begin)

    def read_file(self, path: Path) -> bytearray:
        """The whole file, read in chunks and reported as bytes."""
        with open(path, "rb") as fh:
            return self.read(fh, fh.seek(0, 2) - fh.seek(0))

    def counted(self, stream, pos: int, total: int) -> CountedStream:
        """`stream` (at byte `pos` of `total`) for a reader that takes it line by line or row by row: what it reads
        is reported as bytes, a chunk at a time."""
        return CountedStream(stream, self, pos, total)

    def page_in(self, fh, begin: int, end: int, total: int) -> None:
        """Read bytes begin..end of the file `fh` (which a memory mapping reads later), chunk by chunk, so that they
        come from disk here (into the page cache) and are reported as bytes of `total`; `fh` is left at `end`."""
        buf = memoryview(bytearray(_step(end - begin, MIN_BYTES)))
        fh.seek(begin)
        for a, b in _ranges(end - begin, MIN_BYTES):
            fh.readinto(buf[:b - a])
            self.report(begin + b, total, "bytes")
        fh.seek(end)


class CountedStream:
    """A stream whose read() and readline() report the bytes they consume (see `LoadProgress.counted`)."""

    def __init__(self, stream, progress: LoadProgress, pos: int, total: int) -> None:
        self.stream, self.progress, self.pos, self.total = stream, progress, pos, total
        self._next = pos

    def _advance(self, n: int) -> None:
        self.pos += n
        if self.pos >= self._next:
            self.progress.report(min(self.pos, self.total), self.total, "bytes")
            self._next = self.pos + _step(self.total, MIN_BYTES)

    def read(self, n: int = -1):
        data = self.stream.read(n)
        self._advance(len(data))
        return data

    def readline(self):
        line = self.stream.readline()
        self._advance(len(line))
        return line


def _step(total: int, minimum: int) -> int:
    """The chunk length for `total` units: at most REPORTS chunks, each at least `minimum` long."""
    return max(minimum, -(-total // REPORTS), 1)


def _ranges(total: int, minimum: int) -> Iterator[tuple[int, int]]:
    """Consecutive (begin, end) ranges covering 0..total, `_step` long (but the last)."""
    step = _step(total, minimum)
    for begin in range(0, total, step):
        yield begin, min(total, begin + step)


def row_ranges(rows: int, row_bytes: int) -> list[tuple[int, int]]:
    """(begin, end) ranges of a table of `rows` rows of `row_bytes` bytes, each about a read chunk of bytes."""
    step = max(1, _step(rows * row_bytes, MIN_BYTES) // max(1, row_bytes))
    return [(begin, min(rows, begin + step)) for begin in range(0, rows, step)]


def decode_in_chunks(n: int, decode: Callable[[slice], tuple], progress: LoadProgress) -> tuple:
    """decode(rows) for consecutive row slices of 0..n, reported as splats; its outputs (arrays of n rows, or
    None) joined. A single chunk's outputs are returned as they are."""
    out: list = []
    for begin, end in progress.chunks(n, "splats", MIN_SPLATS):
        parts = decode(slice(begin, end))
        if begin == 0 and end == n:
            out = list(parts)
            continue
        if not out:
            out = [None if p is None else np.empty((n, *p.shape[1:]), p.dtype) for p in parts]
        for o, p in zip(out, parts):
            if o is not None:
                o[begin:end] = p
    return tuple(out)
