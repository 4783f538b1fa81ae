"""Progress and cancellation of a scene load: `gb.load(path, progress=fn, cancel=event)`.

A load goes through up to two phases, each with its unit: "bytes" (the file read from disk, and inflated where the
format is one compressed stream) and then "splats" (decoded into the Scene's arrays). `fn(done, total, unit)` is
called at the start of a phase (done 0), after each chunk, and at its end (done == total): done never decreases
within a unit, and a phase reports at most REPORTS + 2 times. Chunks are at least MIN_BYTES / MIN_SPLATS long, so a
small file is one chunk. Once `cancel` (a gbviewer.CancelToken, a threading.Event or anything with is_set()) is
set, the load raises LoadCancelled at the next chunk. An exception `fn` raises ends the load with a CallbackError
(chained to it), never blamed on the file.

Every byte a loader reads is hashed where it is read (`ContentDigest`), so the scene knows the content it came
from at no extra read: what caches of data derived from its splats key on.
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..core.cancel import Cancellable, cancel_problem
from ..core.errors import CallbackError, InvalidValue, LoadCancelled

Progress = Callable[[int, int, str], None]
REPORTS = 100  # chunks per phase at most
MIN_BYTES = 1 << 20  # smallest chunk of a read
MIN_SPLATS = 1 << 16  # smallest chunk of a decode


class ContentDigest:
    """The SHA-256 digest of the bytes a load read, hashed piece by piece where they are read (from any thread):
    each piece (part, offset, bytes) is hashed on its own, and the pieces' digests are combined in (part, offset)
    order, so the result does not depend on which thread read what when. A part is a file ("" the scene's own;
    a multi-file format's others by name). `hexdigest` is None unless each part's pieces tile it from offset 0
    without a gap or an overlap: a read that went unrecorded gives no digest rather than a wrong one."""

    def __init__(self) -> None:
        self._pieces: dict[tuple[str, int], tuple[int, bytes]] = {}
        self._lock = threading.Lock()
        self._broken = False

    def add(self, part: str, offset: int, data) -> None:
        """Record the bytes `data` read at `offset` of `part`."""
        digest = hashlib.sha256(data).digest()  # releases the GIL: workers hash in parallel
        size = memoryview(data).nbytes
        self._put(part, offset, size, digest)

    def _put(self, part: str, offset: int, size: int, digest: bytes) -> None:
        """Record a piece; a second read of the same bytes (a loader that tried another first) is the same one."""
        with self._lock:
            self._broken |= self._pieces.get((part, offset), (size, digest)) != (size, digest)
            self._pieces[(part, offset)] = (size, digest)

    def stream(self, part: str, offset: int) -> Callable[[bytes | None], None]:
        """A recorder of consecutive reads from `offset` on, hashed as one piece: call it with each read's bytes,
        then with None once the reads are done."""
        h, size = hashlib.sha256(), [0]

        def update(data: bytes | None) -> None:
            if data is None:
                if not size[0]:  # nothing read: no piece
                    return
                self._put(part, offset, size[0], h.digest())
            else:
                h.update(data)
                size[0] += len(data)

        return update

    def hexdigest(self) -> str | None:
        """The digest of every piece recorded, or None when they do not tile their parts (see the class)."""
        with self._lock:
            pieces = sorted(self._pieces.items())
            if self._broken or not pieces:
                return None
        out, part, end = hashlib.sha256(), None, 0
        for (name, offset), (size, digest) in pieces:
            if name != part:
                part, end = name, 0
            if offset != end:
                return None
            end += size
            out.update(f"{name}\0{offset}\0{size}\0".encode("utf-8", "surrogateescape") + digest)
        return out.hexdigest()


class LoadProgress:
    """Reports a load's phases to the caller's `fn` and raises LoadCancelled once `cancel` is set; `digest`: the
    bytes its reads returned (`ContentDigest`)."""

    def __init__(self, fn: Progress | None = None, cancel: Cancellable | None = None) -> None:
        if why := cancel_problem(cancel):
            raise InvalidValue(why)
        self.fn, self.cancel = fn, cancel
        self._last: dict[str, int] = {}
        self.digest = ContentDigest()

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
        got, at = 0, fh.tell()
        for begin, end in self.chunks(size, "bytes", MIN_BYTES):
            n = fh.readinto(view[begin:end])
            self.digest.add("", at + begin, view[begin : begin + n])
            got += n
            if n < end - begin:
                break
        view.release()
        del out[got:]
        self.report(size, size, "bytes")
        return out

    def pieces(self, fh, size: int) -> Iterator[bytes]:
        """The `size` bytes of the binary file `fh` in chunks, each reported as bytes once the caller took it."""
        at = fh.tell()
        for begin, end in self.chunks(size, "bytes", MIN_BYTES):
            piece = fh.read(end - begin)
            self.digest.add("", at + begin, piece)
            yield piece

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
            got = fh.readinto(buf[: b - a])
            self.digest.add("", begin + a, buf[:got])
            self.report(begin + b, total, "bytes")
        fh.seek(end)


class CountedStream:
    """A stream whose read() and readline() report the bytes they consume (see `LoadProgress.counted`) and record
    them in the load's digest from `pos` on (a text stream's characters, counted as such); `finish()` once read."""

    def __init__(self, stream, progress: LoadProgress, pos: int, total: int) -> None:
        self.stream, self.progress, self.pos, self.total = stream, progress, pos, total
        self._next = pos
        self._record = progress.digest.stream("", pos)

    def finish(self) -> None:
        """Close the digest's piece of what was read (call once, after the last read)."""
        self._record(None)

    def _advance(self, n: int) -> None:
        self.pos += n
        if self.pos >= self._next:
            self.progress.report(min(self.pos, self.total), self.total, "bytes")
            self._next = self.pos + _step(self.total, MIN_BYTES)

    def read(self, n: int = -1):
        data = self.stream.read(n)
        self._record(data.encode("ascii", "surrogateescape") if isinstance(data, str) else data)
        self._advance(len(data))
        return data

    def readline(self):
        line = self.stream.readline()
        self._record(line.encode("ascii", "surrogateescape") if isinstance(line, str) else line)
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
