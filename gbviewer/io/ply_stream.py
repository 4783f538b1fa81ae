"""The streamed load of a binary INRIA `.ply` (docs/formats.md#how-a-binary-ply-is-read): worker threads read its
vertex rows a block at a time and scatter them natively straight into the Scene's arrays (`InriaArrays`)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np
import plyfile

from ..core.errors import SceneFormatError
from ..model.scene import Scene
from . import progress as load_progress
from .ply import InriaArrays, inria_layout
from .ply_read import TRUNCATED, checked_header, column_table
from .progress import LoadProgress

SCATTER_BYTES = 4 << 20  # of rows a streamed load reads and scatters at a time (still in cache when scattered)
MAX_LOAD_WORKERS = 8  # a streamed load's threads at most (a SCATTER_BYTES buffer each)


def _streamable(ply: plyfile.PlyData) -> bool:
    """A binary PLY whose first element is a vertex table of scalar properties that only the INRIA loader reads
    (no compressed-ply `chunk` element, no Duplex-GS anchors)."""
    if ply.text or not len(ply.elements) or ply.elements[0].name != "vertex":
        return False
    names = {p.name for p in ply.elements[0].properties}
    return (
        not any(isinstance(p, plyfile.PlyListProperty) for p in ply.elements[0].properties)
        and "chunk" not in {e.name for e in ply.elements}
        and "f_anchor_feat_0" not in names
    )


def _read_at(fh: BinaryIO, lock: threading.Lock, buf: np.ndarray, offset: int) -> bool:
    """Fill `buf` with the bytes of the open file `fh` from `offset` on, from any thread: `os.preadv` where the
    platform has it, else a seek and a read under `lock` (Windows). False when the file ends first."""
    view, got = memoryview(buf).cast("B"), 0
    while got < len(view):
        if hasattr(os, "preadv"):
            n = os.preadv(fh.fileno(), [view[got:]], offset + got)
        else:
            with lock:
                fh.seek(offset + got)
                n = fh.readinto(view[got:])
        if not n:
            return False
        got += n
    return True


def load_streamed_ply(path: Path, progress: LoadProgress | None = None, sh_dtype: str = "float32") -> Scene | None:
    """Load a binary INRIA `.ply` by streaming its vertex rows straight into the Scene's arrays (`InriaArrays`): a
    worker per core (up to MAX_LOAD_WORKERS) takes a hundredth of the file at a time and reads, scatters and
    activates it SCATTER_BYTES at a time on its own thread (no mapping or copy of the whole file: the load costs
    about a read of it, its memory is the arrays' plus SCATTER_BYTES a worker). None when the file is not such a PLY
    (`read_ply` and the other loaders take it). `progress`: bytes read (copied into the arrays and activated).
    `sh_dtype` "float16": the SH is stored as float16 as it is read (see `check_sh_range`)."""
    progress = progress or LoadProgress()
    with open(path, "rb") as fh:
        try:
            size, ply = checked_header(path, fh, progress)
            if not _streamable(ply):
                return None
            element = ply.elements[0]
            row = np.dtype([(p.name, p.dtype(ply.byte_order)) for p in element.properties])
        except (plyfile.PlyParseError, ValueError, UnicodeDecodeError, TypeError):
            return None  # read_ply reports what is wrong with it
        start, n = fh.tell(), element.count
        layout = inria_layout(path, list(row.names), n)
        cols = column_table(path, np.empty(0, row), layout.wanted)[1]  # each column's type checked
        if size - start < n * row.itemsize:
            raise SceneFormatError(path, TRUNCATED, field="vertex")
        out = InriaArrays(layout, n, sh_dtype)
        progress.report(0, size, "bytes")
        ranges = load_progress.row_ranges(n, row.itemsize)
        workers = min(len(ranges), os.cpu_count() or 1, MAX_LOAD_WORKERS)
        block = max(1, SCATTER_BYTES // row.itemsize)  # rows read and scattered at a time
        buffers, lock, errors = threading.local(), threading.Lock(), np.geterr()  # the caller's numpy error state

        def load(k: int) -> None:
            if not hasattr(buffers, "chunk"):
                buffers.chunk = np.empty(min(n, block) * row.itemsize, np.uint8)
            dc = rest = 0.0  # the range's largest |f_dc|, |f_rest| (float16 refuses the range's, not a block's)
            with np.errstate(**errors):
                for begin in range(*ranges[k], block):
                    end = min(begin + block, ranges[k][1])
                    chunk = buffers.chunk[: (end - begin) * row.itemsize]
                    if not _read_at(fh, lock, chunk, start + begin * row.itemsize):
                        raise SceneFormatError(path, TRUNCATED, field="vertex")
                    progress.digest.add("", start + begin * row.itemsize, chunk)
                    table = column_table(path, chunk.view(row), layout.wanted)[0]
                    block_dc, block_rest = out.fill(table, cols, slice(begin, end), 1 if workers > 1 else 0)
                    dc, rest = max(dc, block_dc), max(rest, block_rest)
                    out.activate(slice(begin, end))
            out.check_sh(dc, rest)

        def report(done: Iterator[None]) -> None:
            for (_, end), _ in zip(ranges, done):
                progress.report(start + end * row.itemsize, size, "bytes")

        if workers == 1:  # in this thread (its OpenMP team lasts from load to load)
            report(map(load, range(len(ranges))))
        else:
            with ThreadPoolExecutor(workers) as pool:  # each worker reads, scatters and activates its ranges
                done = pool.map(load, range(len(ranges)))
                try:
                    report(done)
                finally:
                    done.close()  # the ranges not begun are cancelled
        progress.report(size, size, "bytes")
    return out.scene(path)
