"""antimatter15 `.splat`: 32 bytes per splat, no header.

Record: position float32[3], linear scale float32[3], RGBA uint8[4] (colour = 0.5 + SH_C0 * dc,
alpha = sigmoid(opacity)), quaternion uint8[4] as (w, x, y, z) mapped from [-1, 1] by q * 128 + 128.
Positions are in the frame of the source `.ply` (no axis change).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import SceneFormatError
from ..model.scene import SH_C0, Scene
from .packing import check_count
from .progress import LoadProgress, decode_in_chunks

RECORD = np.dtype([("pos", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rot", "u1", 4)])


def looks_like_splat(data: bytes | memoryview) -> bool:
    """Plausibility test for headerless data: whole records, finite positions, finite non-negative scales."""
    if len(data) == 0 or len(data) % RECORD.itemsize:
        return False
    head = np.frombuffer(data, dtype=RECORD, count=min(len(data) // RECORD.itemsize, 4096))
    with np.errstate(invalid="ignore"):
        return bool(
            np.isfinite(head["pos"]).all()
            and np.isfinite(head["scale"]).all()
            and (head["scale"] >= 0).all()
            and (np.abs(head["pos"]) < 1e7).all()
        )


def load_splat(path: Path, data: bytes | memoryview, progress: LoadProgress | None = None) -> Scene:
    """Decode a `.splat` buffer into a Scene; `progress`: splats decoded."""
    if len(data) % RECORD.itemsize:
        raise SceneFormatError(
            path,
            f"size {len(data)} is not a multiple of the {RECORD.itemsize}-byte record (truncated?)",
            field="record",
        )
    n = len(data) // RECORD.itemsize
    check_count(path, n, "record", len(data), RECORD.itemsize)
    rec = np.frombuffer(data, dtype=RECORD, count=n)
    if (rec["scale"] < 0).any():
        raise SceneFormatError(path, "negative scale; .splat stores linear scales >= 0", field="scale")

    def decode(rows: slice) -> tuple:
        r = rec[rows]
        rgba = r["rgba"].astype(np.float32) * np.float32(1 / 255)
        dc = (rgba[:, :3] - np.float32(0.5)) / np.float32(SH_C0)
        quats = (r["rot"].astype(np.float32) - np.float32(128)) / np.float32(128)
        return r["pos"], r["scale"], quats, rgba[:, 3], dc[:, None, :]

    means, scales, quats, opacities, sh = decode_in_chunks(n, decode, progress or LoadProgress())
    meta = {"format": "splat", "version": None, "properties": ["position", "scale", "rgba", "rotation"]}
    return Scene.from_arrays(means, scales, quats, opacities, sh, source=str(path), meta=meta)
