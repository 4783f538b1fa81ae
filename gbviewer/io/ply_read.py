"""Reading a `.ply` with plyfile, whatever its layout (INRIA, compressed, Duplex-GS): the header checked against the
file size before anything is allocated, the used elements read (binary: memory-mapped) with typed errors, and vertex
properties taken as a float32 table."""

from __future__ import annotations

import functools
import io
from pathlib import Path

import numpy as np
import plyfile

from ..core.errors import InvalidValue, SceneFormatError
from ..core.validate import declared_count
from .progress import LoadProgress

HEADER_MAX_BYTES = 1 << 20
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


def checked_header(path: Path, fh, progress: LoadProgress) -> tuple[int, plyfile.PlyData]:
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
            size, ply = checked_header(path, fh, progress)
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
