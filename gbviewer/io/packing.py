"""Helpers shared by the quantised formats: SH constant, smallest-three quaternions, size checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import SceneFormatError

MAX_SPLATS = 1 << 28  # refuse header counts beyond this before allocating anything

_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


def smallest_three(others: np.ndarray, largest: np.ndarray) -> np.ndarray:
    """(N,4) quaternions from the three smaller components (in index order) and the index of the largest.

    The largest component is rebuilt as sqrt(1 - sum of squares), so it is non-negative.
    """
    others = np.asarray(others, dtype=np.float32)
    q = np.empty((others.shape[0], 4), dtype=np.float32)
    rows = np.arange(others.shape[0])[:, None]
    q[rows, _OTHERS[largest]] = others
    q[rows[:, 0], largest] = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", others, others)))
    return q


def check_count(path: Path, count: int, field: str, available_bytes: int, bytes_per_splat: float) -> None:
    """Reject a header count of zero, an absurd count, or one larger than the data can hold."""
    if count <= 0:
        raise SceneFormatError(path, f"zero splats (count {count})", field=field)
    if count > MAX_SPLATS:
        raise SceneFormatError(path, f"count {count} exceeds the supported maximum {MAX_SPLATS}", field=field)
    if count * bytes_per_splat > available_bytes:
        raise SceneFormatError(
            path,
            f"count {count} needs at least {int(count * bytes_per_splat)} bytes of data but the file has "
            f"{available_bytes}",
            field=field,
        )
