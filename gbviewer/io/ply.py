"""INRIA 3DGS `.ply` (KERNELS.md §1.1): raw parameters per vertex, activated on load.

Also the sort-free GS layout (KERNELS.md §1.2): the INRIA columns plus `f_do_0`, `f_ro_*` (the view weight v_i as a
raw 1-channel SH, kept as `Scene.oit.view_weight_sh`) and `info`, a column that carries the globals in its first rows:
info[0] = weight_background, info[1] = sigma."""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Callable

import numpy as np
import plyfile

from ..errors import InvalidValue, SceneFormatError
from ..scene import Scene
from ..validate import declared_count
from .progress import LoadProgress, decode_in_chunks

HEADER_MAX_BYTES = 1 << 20
USED_ELEMENTS = ("vertex", "chunk", "sh")  # what the loaders read; elements after the last of these stay unread
TYPE_BYTES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}

REQUIRED = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
            "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}  # f_rest_* count -> SH degree
REST_COUNTS_1 = {0: 0, 3: 1, 8: 2, 15: 3}  # f_ro_* count (1-channel view weight) -> SH degree


def read_ply(path: Path, progress: LoadProgress | None = None) -> plyfile.PlyData:
    """Parse a PLY header and read (binary: memory-map) the elements the loaders use, with typed errors for non-PLY
    and truncated files. Elements after the last used one (a mesh's faces, say) are never read: plyfile would parse
    their lists row by row into memory. Counts are checked against the file size first (`check_element_counts`).
    `progress`: file bytes read (a mapped element is paged in chunk by chunk, so that its bytes are read here)."""
    progress = progress or LoadProgress()
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEADER_MAX_BYTES)
            if not (head.startswith(b"ply\n") or head.startswith(b"ply\r\n")):
                raise SceneFormatError(path, "not a PLY file (missing 'ply' magic line)")
            size = fh.seek(0, 2)
            check_element_counts(path, head, size)
            fh.seek(0)
            progress.report(0, size, "bytes")
            # plyfile's PlyData.read, stopping early: the same header parser and per-element reader it uses
            ply = plyfile.PlyData._parse_header(fh)
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
            progress.report(size, size, "bytes")
        return ply
    except plyfile.PlyElementParseError as exc:
        raise SceneFormatError(path, f"truncated or malformed data: {exc.message}",
                               field=exc.element.name if exc.element is not None else None) from None
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
    binary = any(line.split()[:2] in (["format", "binary_little_endian"], ["format", "binary_big_endian"])
                 for line in lines if line.strip())
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


def vertex_columns(path: Path, ply: plyfile.PlyData, names: list[str]) -> Callable[..., np.ndarray]:
    """Check that each named vertex property is a scalar number; return `columns(names, rows=all) -> (rows, len)
    float32`.

    For the usual all-float32 layout, consecutive properties come back as a strided view of the memory-mapped
    data, so each byte is copied once, by whoever makes the final array."""
    data = ply["vertex"].data
    fields = data.dtype.fields or {}
    for name in names:
        if name not in fields:
            raise SceneFormatError(path, "missing required property", field=name)
        dtype = fields[name][0]
        if dtype.kind not in "fiu" or dtype.shape:
            raise SceneFormatError(path, f"property has type {dtype}; expected a scalar number", field=name)
    all_names = list(data.dtype.names)
    if all(fields[n][0] == np.dtype("<f4") for n in all_names) and data.dtype.itemsize == 4 * len(all_names):
        flat = np.asarray(data).view("<f4").reshape(len(data), len(all_names))
        pos = {n: i for i, n in enumerate(all_names)}

        def columns(wanted: list[str], rows: slice = slice(None)) -> np.ndarray:
            idx = [pos[n] for n in wanted]
            if idx == list(range(idx[0], idx[0] + len(idx))):
                return flat[rows, idx[0]:idx[0] + len(idx)]
            return np.take(flat[rows], idx, axis=1)

        return columns
    return lambda wanted, rows=slice(None): np.stack([np.asarray(data[n][rows], dtype=np.float32) for n in wanted],
                                                     axis=1)


def activate_opacity(raw: np.ndarray) -> np.ndarray:
    """sigmoid in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-raw))


def activate_scales(raw: np.ndarray) -> np.ndarray:
    """exp in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return np.exp(raw)


def load_inria_ply(path: Path, ply: plyfile.PlyData, progress: LoadProgress | None = None) -> Scene:
    """Load an INRIA-layout splat PLY: exp scales, sigmoid opacity, normalised (w,x,y,z) quaternions. `progress`:
    splats decoded."""
    if "vertex" not in ply:
        raise SceneFormatError(path, "no 'vertex' element", field="vertex")
    names = list(ply["vertex"].data.dtype.names or ())
    if ply["vertex"].count == 0:
        raise SceneFormatError(path, "zero splats", field="vertex")
    rest_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_rest_(\d+)", n)))
    if len(rest_idx) not in REST_COUNTS or rest_idx != list(range(len(rest_idx))):
        raise SceneFormatError(
            path, f"{len(rest_idx)} f_rest_* properties (indices {rest_idx[:3]}...); expected f_rest_0.. with "
            "0, 9, 24 or 45 of them (SH degree 0-3)", field="f_rest")
    degree = REST_COUNTS[len(rest_idx)]
    has_filter = "filter_3D" in names
    rest = [f"f_rest_{i}" for i in rest_idx]
    ro_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_ro_(\d+)", n)))
    sort_free = "f_do_0" in names or bool(ro_idx)
    weight_cols: list[str] = []
    if sort_free:
        if "f_do_0" not in names or len(ro_idx) not in REST_COUNTS_1 or ro_idx != list(range(len(ro_idx))):
            raise SceneFormatError(
                path, f"sort-free view weight: f_do_0 {'present' if 'f_do_0' in names else 'missing'} and "
                f"{len(ro_idx)} f_ro_* properties; expected f_do_0 and f_ro_0.. with 0, 3, 8 or 15 of them",
                field="f_ro")
        if "info" not in names:
            raise SceneFormatError(path, "sort-free layout (f_do_0) without the 'info' column that holds "
                                   "weight_background and sigma", field="info")
        weight_cols = ["f_do_0"] + [f"f_ro_{i}" for i in ro_idx] + ["info"]
    columns = vertex_columns(path, ply, REQUIRED + rest + (["filter_3D"] if has_filter else []) + weight_cols)
    n = ply["vertex"].count
    k = (degree + 1) ** 2
    meta = {"format": "inria-ply", "version": None, "properties": names, "sh_degree": degree,
            "filter_3D": has_filter}
    extra: dict = {}
    if sort_free:
        info = columns(["info"], slice(0, 2))[:, 0]
        if n < 2:
            raise SceneFormatError(path, f"sort-free layout with {n} vertex; the info column needs 2 rows "
                                   "(weight_background, sigma)", field="info")
        wbg, sigma = float(info[0]), float(info[1])
        if not (np.isfinite(wbg) and wbg >= 0 and np.isfinite(sigma) and sigma > 0):
            raise SceneFormatError(path, f"info rows 0, 1 (weight_background, sigma) = {wbg}, {sigma}; expected "
                                   "weight_background >= 0 and sigma > 0", field="info")
        extra = {"weight_background": wbg, "wsr_sigma": sigma}
        meta.update(format="sort-free-ply", sort_free=True)

    sh = np.empty((n, k, 3), dtype=np.float32)  # filled in place: the largest array, not copied again

    def decode(rows: slice) -> tuple:
        sh[rows, 0, :] = columns(["f_dc_0", "f_dc_1", "f_dc_2"], rows)
        if k > 1:  # f_rest is channel-major: all R coefficients, then G, then B
            sh[rows, 1:, :] = columns(rest, rows).reshape(-1, 3, k - 1).transpose(0, 2, 1)
        return (columns(["x", "y", "z"], rows), activate_scales(columns(["scale_0", "scale_1", "scale_2"], rows)),
                columns(["rot_0", "rot_1", "rot_2", "rot_3"], rows), activate_opacity(columns(["opacity"], rows)[:, 0]),
                columns(["filter_3D"], rows)[:, 0] if has_filter else None,
                columns(weight_cols[:-1], rows) if sort_free else None)

    means, scales, quats, opacities, filter_3d, view_weight_sh = decode_in_chunks(n, decode,
                                                                                  progress or LoadProgress())
    if sort_free:
        extra["view_weight_sh"] = view_weight_sh
    return Scene.from_arrays(means, scales, quats, opacities, sh, filter_3d, source=str(path), meta=meta, **extra)
