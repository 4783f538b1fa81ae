"""INRIA 3DGS `.ply` (docs/formats.md#inria-3dgs-ply): raw parameters per vertex, activated on load.

Also the sort-free GS layout (docs/formats.md#variant-layouts): the INRIA columns plus `f_do_0`, `f_ro_*` (the view
weight v_i as a raw 1-channel SH, kept as `Scene.oit.view_weight_sh`) and `info`, a column that carries the globals in
its first rows: info[0] = weight_background, info[1] = sigma."""

from __future__ import annotations

import functools
import importlib
import io
import os
import re
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np
import plyfile

from ..core.errors import GBViewerError, InvalidValue, SceneFormatError
from ..core.validate import declared_count
from ..model.scene import MAX_SCALE, MAX_SH, Checked, Scene
from . import progress as load_progress
from .progress import LoadProgress

HEADER_MAX_BYTES = 1 << 20
SCATTER_BYTES = 4 << 20  # of rows a streamed load reads and scatters at a time (still in cache when scattered)
MAX_LOAD_WORKERS = 8  # a streamed load's threads at most (a SCATTER_BYTES buffer each)
TRUNCATED = "truncated or malformed data: early end-of-file"
USED_ELEMENTS = ("vertex", "chunk", "sh")  # what the loaders read; elements after the last of these stay unread
TYPE_BYTES = {
    "char": 1,
    "uchar": 1,
    "int8": 1,
    "uint8": 1,
    "short": 2,
    "ushort": 2,
    "int16": 2,
    "uint16": 2,
    "int": 4,
    "uint": 4,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "float32": 4,
    "double": 8,
    "float64": 8,
}

REQUIRED = [
    "x",
    "y",
    "z",
    "f_dc_0",
    "f_dc_1",
    "f_dc_2",
    "opacity",
    "scale_0",
    "scale_1",
    "scale_2",
    "rot_0",
    "rot_1",
    "rot_2",
    "rot_3",
]
REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}  # f_rest_* count -> SH degree
REST_COUNTS_1 = {0: 0, 3: 1, 8: 2, 15: 3}  # f_ro_* count (1-channel view weight) -> SH degree


def _checked_header(path: Path, fh, progress: LoadProgress) -> tuple[int, plyfile.PlyData]:
    """Check the magic line and the element counts of the PLY open as `fh`, then parse its header (`fh` left at its
    end, its bytes recorded in the load's digest); returns the file size and the header."""
    head = fh.read(HEADER_MAX_BYTES)
    if not (head.startswith(b"ply\n") or head.startswith(b"ply\r\n")):
        raise SceneFormatError(path, "not a PLY file (missing 'ply' magic line)")
    size = fh.seek(0, 2)
    check_element_counts(path, head, size)
    fh.seek(0)
    ply = plyfile.PlyData._parse_header(fh)
    progress.digest.add("", 0, head[: fh.tell()])  # a header longer than `head` leaves a gap: no digest
    return size, ply


def read_ply(path: Path, progress: LoadProgress | None = None) -> plyfile.PlyData:
    """Parse a PLY header and read (binary: memory-map) the elements the loaders use, with typed errors for non-PLY
    and truncated files. Elements after the last used one (a mesh's faces, say) are never read: plyfile would parse
    their lists row by row into memory. Counts are checked against the file size first (`check_element_counts`).
    `progress`: file bytes read (a mapped element is paged in chunk by chunk, so that its bytes are read here)."""
    progress = progress or LoadProgress()
    try:
        with open(path, "rb") as fh:
            # plyfile's PlyData.read, stopping early: the same header parser and per-element reader it uses
            size, ply = _checked_header(path, fh, progress)
            progress.report(0, size, "bytes")
            stream = io.TextIOWrapper(fh, "ascii") if ply.text else fh
            used = [i for i, e in enumerate(ply.elements) if e.name in USED_ELEMENTS]
            ply.elements = ply.elements[: used[-1] + 1] if used else ()
            counted = progress.counted(stream, fh.tell(), size)
            for element in ply.elements:
                begin = fh.tell()
                rows = ply.text or any(isinstance(p, plyfile.PlyListProperty) for p in element.properties)
                element._read(counted if rows else stream, ply.text, ply.byte_order, "c")
                if not rows:  # memory-mapped by plyfile
                    progress.page_in(fh, begin, fh.tell(), size)
                    counted.pos = fh.tell()
            counted.finish()
            progress.report(size, size, "bytes")
        return ply
    except plyfile.PlyElementParseError as exc:
        raise SceneFormatError(
            path,
            f"truncated or malformed data: {exc.message}",
            field=exc.element.name if exc.element is not None else None,
        ) from None
    except plyfile.PlyParseError as exc:
        raise SceneFormatError(path, f"malformed PLY header: {exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise SceneFormatError(path, f"malformed PLY: {exc}") from None


def check_element_counts(path: Path, head: bytes, size: int) -> None:
    """Before plyfile allocates anything: every element count the header (in `head`, the first bytes of the
    `size`-byte file) declares must fit in the bytes that follow it (binary: count x the smallest row; ASCII: two
    characters per value), so a small file cannot ask for terabytes or for a count that does not fit an index."""
    end = head.find(b"end_header")
    if end < 0:
        return  # no complete header: plyfile reports it
    lines = head[:end].decode("ascii", "replace").splitlines()
    binary = any(
        line.split()[:2] in (["format", "binary_little_endian"], ["format", "binary_big_endian"])
        for line in lines
        if line.strip()
    )
    elements: list[list] = []  # [name, count, smallest row bytes]
    for line in lines:
        words = line.split()
        if len(words) == 3 and words[0] == "element":
            elements.append([words[1], words[2], 0])
        elif elements and len(words) >= 3 and words[0] == "property":
            elements[-1][2] += TYPE_BYTES.get(words[2] if words[1] == "list" else words[1], 1) if binary else 2
    available = size - end
    for name, count, row in elements:
        try:
            available -= declared_count(count, f"element '{name}'", item_bytes=row, available=available) * row
        except InvalidValue as exc:
            raise SceneFormatError(path, str(exc).removeprefix(f"element '{name}': "), field=name) from None


def vertex_columns(path: Path, ply: plyfile.PlyData, names: list[str]) -> np.ndarray:
    """The named vertex properties (each checked to be a scalar number) as a (rows, len(names)) float32 array."""
    table, pos = column_table(path, ply["vertex"].data, names)
    return table if list(pos) == list(range(table.shape[1])) else np.take(table, pos, axis=1)


def column_table(path: Path, data: np.ndarray, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """A structured array of vertex rows as a (rows, C) float32 table and the int32 positions of `names` in it, once
    each named property is checked to be a scalar number. The usual all-float32 layout is viewed as it is (memory-
    mapped or a chunk read from the file: each byte is copied once, by the scatter into the final arrays); other
    layouts are converted, the named columns only."""
    viewed, pos = _table_layout(path, data.dtype, tuple(names))
    if viewed:
        return np.asarray(data).view(np.float32).reshape(len(data), len(data.dtype.names)), np.array(pos, np.int32)
    table = np.stack([np.asarray(data[n], dtype=np.float32) for n in names], axis=1)
    return table, np.arange(len(names), dtype=np.int32)


@functools.lru_cache(maxsize=16)
def _table_layout(path: Path, dtype: np.dtype, names: tuple[str, ...]) -> tuple[bool, tuple[int, ...]]:
    """`column_table`'s checks of a row type, and whether its rows are viewed as they are (then the positions of
    `names`); once per row type (a streamed load asks for every block it reads)."""
    fields = dtype.fields or {}
    for name in names:
        if name not in fields:
            raise SceneFormatError(path, "missing required property", field=name)
        if fields[name][0].kind not in "fiu" or fields[name][0].shape:
            raise SceneFormatError(path, f"property has type {fields[name][0]}; expected a scalar number", field=name)
    all_names = list(dtype.names)
    if all(fields[n][0] == np.dtype("=f4") for n in all_names) and dtype.itemsize == 4 * len(all_names):
        return True, tuple(all_names.index(n) for n in names)
    return False, ()


def check_sh_range(sh: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """`sh`, once checked to fit `dtype` (`check_sh_magnitude`)."""
    if np.dtype(dtype) == np.float16 and sh.size:
        check_sh_magnitude(max(float(np.fmax.reduce(sh, axis=None)), -float(np.fmin.reduce(sh, axis=None))), dtype)
    return sh


def check_sh_magnitude(big: float, dtype: np.dtype) -> None:
    """float16 storage (`gb.load(..., sh_dtype="float16")`) refuses SH coefficients up to `big` in magnitude when that
    is beyond its largest finite value, rather than turning them into infinities."""
    if np.dtype(dtype) == np.float16 and big > float(np.finfo(np.float16).max):
        raise GBViewerError(
            f"field 'sh': coefficients up to {big:.3g}, beyond float16's range (65504); load with sh_dtype='float32'"
        )


def native_io():
    """`gbviewer._native.io` (the INRIA row scatter), or a GBViewerError saying why the native module does not
    import (a GBVIEWER_SIMD the CPU lacks, say): imported here, not with gbviewer, which imports without it. By
    name: the compiled module is a leaf that imports nothing of gbviewer, but the import linter, which sees only
    .py files, would take `from .. import _native` for an import of the whole package (and so of render)."""
    try:
        return importlib.import_module("gbviewer._native").io
    except ImportError as exc:
        raise GBViewerError(
            f"the native module gbviewer._native does not import ({exc}); the .ply loader needs it"
        ) from None


def activate_opacity(raw: np.ndarray) -> np.ndarray:
    """sigmoid in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-raw))


def activate_scales(raw: np.ndarray) -> np.ndarray:
    """exp in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return np.exp(raw)


@dataclass(frozen=True)
class InriaLayout:
    """What an INRIA vertex table holds (checked by `inria_layout`): its properties, SH degree and f_rest columns, a
    filter_3D column, and for the sort-free layout its view-weight columns (f_do_0, f_ro_*) and `info`."""

    names: list[str]
    degree: int
    rest: list[str]
    has_filter: bool
    weight_cols: list[str]

    @property
    def wanted(self) -> list[str]:
        return REQUIRED + self.rest + (["filter_3D"] if self.has_filter else []) + self.weight_cols


def inria_layout(path: Path, names: list[str], n: int) -> InriaLayout:
    """The layout of an `n`-row INRIA vertex table with properties `names`, or a SceneFormatError saying what is
    wrong with it (no rows, f_rest_* or f_ro_* counts, a sort-free table without `info`)."""
    if n == 0:
        raise SceneFormatError(path, "zero splats", field="vertex")
    rest_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_rest_(\d+)", n)))
    if len(rest_idx) not in REST_COUNTS or rest_idx != list(range(len(rest_idx))):
        raise SceneFormatError(
            path,
            f"{len(rest_idx)} f_rest_* properties (indices {rest_idx[:3]}...); expected f_rest_0.. with "
            "0, 9, 24 or 45 of them (SH degree 0-3)",
            field="f_rest",
        )
    ro_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_ro_(\d+)", n)))
    weight_cols: list[str] = []
    if "f_do_0" in names or ro_idx:
        if "f_do_0" not in names or len(ro_idx) not in REST_COUNTS_1 or ro_idx != list(range(len(ro_idx))):
            raise SceneFormatError(
                path,
                f"sort-free view weight: f_do_0 {'present' if 'f_do_0' in names else 'missing'} and "
                f"{len(ro_idx)} f_ro_* properties; expected f_do_0 and f_ro_0.. with 0, 3, 8 or 15 of them",
                field="f_ro",
            )
        if "info" not in names:
            raise SceneFormatError(
                path,
                "sort-free layout (f_do_0) without the 'info' column that holds weight_background and sigma",
                field="info",
            )
        weight_cols = ["f_do_0"] + [f"f_ro_{i}" for i in ro_idx] + ["info"]
    return InriaLayout(
        names, REST_COUNTS[len(rest_idx)], [f"f_rest_{i}" for i in rest_idx], "filter_3D" in names, weight_cols
    )


class InriaArrays:
    """The Scene's final arrays of an INRIA load, allocated once: `fill` copies raw columns into them a row range
    at a time (no array of the whole file besides them), `activate` applies exp and sigmoid in place."""

    def __init__(self, layout: InriaLayout, n: int, sh_dtype: str = "float32") -> None:
        self.layout, self.n, k = layout, n, (layout.degree + 1) ** 2
        self.means, self.scales = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
        self.quats, self.opacities = np.empty((n, 4), np.float32), np.empty(n, np.float32)
        self.sh = np.empty((n, k, 3), sh_dtype)
        self.filter_3d = np.empty(n, np.float32) if layout.has_filter else None
        self.weights = np.empty((n, len(layout.weight_cols) - 1), np.float32) if layout.weight_cols else None
        self.info = np.zeros(min(n, 2), np.float32)
        self.keep = np.empty(n, bool)
        self._scatter = native_io().scatter_inria

    def fill(self, table: np.ndarray, cols: np.ndarray, rows: slice, threads: int = 0) -> tuple[float, float]:
        """Scatter `table` (rows, C) float32, the raw rows `rows`, its columns at `cols` (`column_table` of
        `layout.wanted`) into the arrays: copied, checked and normalised as Scene.from_arrays would
        (`gbviewer._native.io.scatter_inria` on `threads` threads, 0: all; `keep` marks the splats it would keep).
        Calls for different rows may run at once. Returns the rows' largest |f_dc| and |f_rest| for `check_sh`."""
        sliced = [None if a is None else a[rows] for a in (self.filter_3d, self.weights)]
        maxima = self._scatter(
            table,
            cols[:-1] if self.weights is not None else cols,
            self.means[rows],
            self.scales[rows],
            self.quats[rows],
            self.opacities[rows],
            self.sh[rows],
            *sliced,
            self.keep.view(np.uint8)[rows],
            MAX_SH,
            threads,
        )
        if self.weights is not None and rows.start < len(self.info):
            head = table[: len(self.info) - rows.start, cols[-1]]
            self.info[rows.start : rows.start + len(head)] = head
        return maxima

    def check_sh(self, dc: float, rest: float) -> None:
        """Refuse SH coefficients as large as `fill` found (the DC block's first) when the storage cannot hold them."""
        check_sh_magnitude(dc, self.sh.dtype)
        check_sh_magnitude(rest, self.sh.dtype)

    def activate(self, rows: slice) -> None:
        """exp of the scales, sigmoid of the opacities of rows `rows`, in place; `keep` then also drops the splats
        whose activated scale is beyond MAX_SCALE (or not finite) and whose opacity is NaN, as Scene.from_arrays."""
        scales, opacities = self.scales[rows], self.opacities[rows]
        scales[...] = activate_scales(scales)
        opacities[...] = activate_opacity(opacities)
        ok = scales <= np.float32(MAX_SCALE)
        if not ok.all():  # the per-splat reduction only where a chunk has such a scale
            self.keep[rows] &= ok.all(axis=1)
        self.keep[rows] &= ~np.isnan(opacities)

    def scene(self, path: Path) -> Scene:
        """The validated Scene of the filled, activated arrays."""
        layout, n = self.layout, self.n
        meta = {
            "format": "inria-ply",
            "version": None,
            "properties": layout.names,
            "sh_degree": layout.degree,
            "filter_3D": layout.has_filter,
        }
        extra: dict = {}
        if self.weights is not None:
            if n < 2:
                raise SceneFormatError(
                    path,
                    f"sort-free layout with {n} vertex; the info column needs 2 rows (weight_background, sigma)",
                    field="info",
                )
            wbg, sigma = float(self.info[0]), float(self.info[1])
            if not (np.isfinite(wbg) and wbg >= 0 and np.isfinite(sigma) and sigma > 0):
                raise SceneFormatError(
                    path,
                    f"info rows 0, 1 (weight_background, sigma) = {wbg}, {sigma}; expected "
                    "weight_background >= 0 and sigma > 0",
                    field="info",
                )
            extra = {"weight_background": wbg, "wsr_sigma": sigma, "view_weight_sh": self.weights}
            meta.update(format="sort-free-ply", sort_free=True)
        return Scene.from_arrays(
            self.means,
            self.scales,
            self.quats,
            self.opacities,
            self.sh,
            self.filter_3d,
            source=str(path),
            meta=meta,
            checked=Checked(self.keep),
            **extra,
        )


def load_inria_ply(path: Path, ply: plyfile.PlyData, progress: LoadProgress | None = None) -> Scene:
    """Load an INRIA-layout splat PLY read by `read_ply` (ASCII, or binary that `load_streamed_ply` leaves): exp
    scales, sigmoid opacity, normalised (w,x,y,z) quaternions. `progress`: splats decoded."""
    if "vertex" not in ply:
        raise SceneFormatError(path, "no 'vertex' element", field="vertex")
    n = ply["vertex"].count
    layout = inria_layout(path, list(ply["vertex"].data.dtype.names or ()), n)
    table, cols = column_table(path, ply["vertex"].data, layout.wanted)
    out = InriaArrays(layout, n)
    for begin, end in (progress or LoadProgress()).chunks(n, "splats", load_progress.MIN_SPLATS):
        rows = slice(begin, end)
        out.check_sh(*out.fill(table[rows], cols, rows))
        out.activate(rows)
    return out.scene(path)


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
            size, ply = _checked_header(path, fh, progress)
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
