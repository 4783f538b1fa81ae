"""PlayCanvas / SuperSplat compressed `.ply`: per-chunk ranges plus 32-bit packed splats.

Element `chunk` (one per 256 splats, float32): min/max of x, y, z and of the log scales, and in the
18-property variant min/max of r, g, b. Element `vertex` (uint32): packed_position and packed_scale
(11/10/11-bit fractions of the chunk range), packed_rotation (2-bit index of the largest component of
(w, x, y, z), then three 10-bit components in [-1/sqrt2, 1/sqrt2]), packed_color (RGBA bytes; RGB
within the chunk colour range, or 0..1 without one; colour = 0.5 + SH_C0 * dc; A = sigmoid(opacity)).
Optional element `sh` (uint8 f_rest_*, INRIA channel-major order): ((v + 0.5) / 256 - 0.5) * 8 with
0 and 255 mapping to the ends of the range. Positions are in the source `.ply` frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import plyfile

from ..core.errors import SceneFormatError
from ..model.scene import SH_C0, Scene
from .packing import smallest_three
from .progress import LoadProgress, decode_in_chunks

CHUNK_SIZE = 256
RANGE_PROPS = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
]
COLOR_PROPS = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"]
PACKED_PROPS = ["packed_position", "packed_rotation", "packed_scale", "packed_color"]
SH_COUNTS = {9: 1, 24: 2, 45: 3}


def is_compressed_ply(ply: plyfile.PlyData) -> bool:
    """True when the file has a `chunk` element and packed vertex properties."""
    names = {e.name for e in ply.elements}
    return "chunk" in names and "vertex" in names and "packed_position" in ply["vertex"].data.dtype.names


def _columns(path: Path, element: plyfile.PlyElement, names: list[str], kind: str) -> list[np.ndarray]:
    fields = element.data.dtype.fields
    for name in names:
        if name not in fields:
            raise SceneFormatError(path, f"missing property in element '{element.name}'", field=name)
        got, want = fields[name][0], np.dtype(kind)
        if (got.kind, got.itemsize, got.shape) != (want.kind, want.itemsize, ()):
            raise SceneFormatError(path, f"property has type {got}; expected {want}", field=name)
    return [np.asarray(element.data[name]) for name in names]


def _fractions(packed: np.ndarray) -> np.ndarray:
    """11/10/11-bit unsigned fractions (x high, z low) as (N, 3) float32."""
    shifts, masks = np.array([21, 11, 0], np.uint32), np.array([2047, 1023, 2047], np.uint32)
    return ((packed[:, None] >> shifts) & masks).astype(np.float32) / masks.astype(np.float32)


def load_compressed_ply(path: Path, ply: plyfile.PlyData, progress: LoadProgress | None = None) -> Scene:
    """Decode a compressed `.ply` (12- or 18-property chunks, optional SH) into a Scene; `progress`: splats
    decoded."""
    chunk, vertex = ply["chunk"], ply["vertex"]
    n = vertex.count
    if n == 0:
        raise SceneFormatError(path, "zero splats", field="vertex")
    if chunk.count != math.ceil(n / CHUNK_SIZE):
        raise SceneFormatError(
            path, f"{chunk.count} chunks for {n} splats; expected {math.ceil(n / CHUNK_SIZE)}", field="chunk"
        )
    has_color = "min_r" in chunk.data.dtype.names
    ranges = np.stack(_columns(path, chunk, RANGE_PROPS + (COLOR_PROPS if has_color else []), "<f4"), axis=1)
    ranges = ranges.astype(np.float32)
    pos, rot, scl, col = _columns(path, vertex, PACKED_PROPS, "<u4")
    rest = _sh_rest(path, ply["sh"], n) if "sh" in ply else None

    def decode(rows: slice) -> tuple:
        r = ranges[np.arange(rows.start, rows.stop) // CHUNK_SIZE]  # each splat's chunk ranges

        def lerp(lo: int, t: np.ndarray) -> np.ndarray:
            return r[:, lo : lo + 3] + (r[:, lo + 3 : lo + 6] - r[:, lo : lo + 3]) * t

        means = lerp(0, _fractions(pos[rows].astype(np.uint32)))
        scales = np.exp(lerp(6, _fractions(scl[rows].astype(np.uint32))))
        packed = rot[rows].astype(np.uint32)
        comps = ((packed[:, None] >> np.array([20, 10, 0], np.uint32)) & 1023).astype(np.float32)
        quats = smallest_three(
            (comps / np.float32(1023) - np.float32(0.5)) * np.float32(math.sqrt(2)), (packed >> 30).astype(np.intp)
        )
        rgba = ((col[rows].astype(np.uint32)[:, None] >> np.array([24, 16, 8, 0], np.uint32)) & 255).astype(
            np.float32
        ) / np.float32(255)
        rgb = lerp(12, rgba[:, :3]) if has_color else rgba[:, :3]
        sh = ((rgb - np.float32(0.5)) / np.float32(SH_C0))[:, None, :]
        if rest is not None:
            sh = np.concatenate([sh, rest(rows)], axis=1)
        return means, scales, quats, rgba[:, 3], sh

    means, scales, quats, opacities, sh = decode_in_chunks(n, decode, progress or LoadProgress())
    names = [p.name for e in ply.elements for p in e.properties]
    meta = {"format": "compressed-ply", "version": f"{len(ranges[0])}-property chunks", "properties": names}
    return Scene.from_arrays(means, scales, quats, opacities, sh, source=str(path), meta=meta)


def _sh_rest(path: Path, element: plyfile.PlyElement, n: int) -> Callable[[slice], np.ndarray]:
    """The `sh` element's uint8 f_rest_*: rows -> (rows, K-1, 3) coefficients."""
    k3 = len(element.properties)
    if k3 not in SH_COUNTS or element.count != n:
        raise SceneFormatError(
            path,
            f"{k3} properties x {element.count} rows; expected 9, 24 or 45 f_rest_* properties and {n} rows",
            field="sh",
        )
    columns = _columns(path, element, [f"f_rest_{i}" for i in range(k3)], "u1")
    data = element.data
    if data.dtype.itemsize == k3 and list(data.dtype.names) == [f"f_rest_{i}" for i in range(k3)]:
        cols = np.asarray(data).view(np.uint8).reshape(n, k3)  # the usual layout: one (N, K3) byte view
    else:
        cols = np.stack(columns, axis=1)
    lut = ((np.arange(256, dtype=np.float32) + 0.5) / 256 - 0.5) * 8
    lut[0], lut[255] = -4.0, 4.0
    return lambda rows: lut[cols[rows]].reshape(-1, 3, k3 // 3).transpose(0, 2, 1)
