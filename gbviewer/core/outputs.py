"""Outputs never destroy inputs: an output path that is (through symlinks, hard links or `..`) one of the command's
inputs, or an existing file inside an input folder, is refused with or without --force; outputs of one run that
would land on the same file are refused before the work."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from .errors import GBViewerError

PathLike = str | os.PathLike


def _identity(path: Path) -> tuple[int, int] | None:
    """(st_dev, st_ino) of the file `path` names (symlinks followed), None where there is none."""
    try:
        st = path.stat()
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def _inside(path: Path, folder: Path) -> bool:
    return path != folder and folder in path.parents


def refuse_inputs(outputs: Iterable[PathLike | None], inputs: Iterable[PathLike | None]) -> None:
    """Raise a one-line `GBViewerError` when an output would overwrite an input: the same file (after resolving
    symlinks and relative parts, or a hard link to it: same device and inode) or an existing file inside an input
    folder (a SOG folder, a dataset). None entries are skipped."""
    given = [Path(p) for p in inputs if p is not None]
    real = [(p, Path(os.path.realpath(p)), _identity(p)) for p in given]
    for out in (Path(p) for p in outputs if p is not None):
        out_real, out_id = Path(os.path.realpath(out)), _identity(out)
        for src, src_real, src_id in real:
            same = out_real == src_real or (out_id is not None and out_id == src_id)
            if same or (out_id is not None and src_real.is_dir() and _inside(out_real, src_real)):
                what = "is" if same else "lies inside"
                raise GBViewerError(
                    f"{out}: {what} the input {src}; choose another output (refused even with "
                    "--force, the input would be lost)"
                )


def refuse_collisions(outputs: Iterable[PathLike], what: str = "outputs") -> None:
    """Raise a one-line `GBViewerError` when two of one run's `outputs` resolve to the same file (two scenes of the
    same name plotted into one folder), before any work."""
    seen: dict[Path, Path] = {}
    for out in map(Path, outputs):
        key = Path(os.path.realpath(out))
        if key in seen:
            raise GBViewerError(
                f"{out}: two {what} would be written to this one file ({seen[key]} and {out}); "
                "rename a scene or write them to separate folders"
            )
        seen[key] = out
