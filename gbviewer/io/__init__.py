"""Scene loading: `load(path)` detects the format by content and returns a validated `Scene`."""

from __future__ import annotations

from pathlib import Path

from ..camera import load_cameras_json
from ..errors import SceneFormatError
from ..scene import Scene
from .ply import load_inria_ply, read_ply

__all__ = ["load", "load_cameras_json"]


def load(path: str | Path) -> Scene:
    """Load a splat scene file (format detected from its first bytes, not its extension)."""
    path = Path(path)
    if not path.is_file():
        raise SceneFormatError(path, "no such file" if not path.exists() else "not a regular file")
    with open(path, "rb") as fh:
        head = fh.read(16)
    if head.startswith(b"ply"):
        return load_inria_ply(path, read_ply(path))
    raise SceneFormatError(path, "unrecognised scene format; expected an INRIA 3DGS .ply")
