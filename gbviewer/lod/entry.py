"""A hierarchy cache entry read as the untrusted input it is: an .npz (numpy's zip of .npy members) whose members
must be exactly the arrays of the scene's hierarchy (`tree.layout`); each member's header (dtype, shape, order) is
checked before its data is read, so a damaged or hostile entry allocates no more than the scene's tree, and the
values are then checked whole (`Hierarchy.check`) before the cut or a renderer sees them. Only a regular file is
read (a FIFO or a device put in its place, or a link to one, would block or never end). Any problem raises
(ValueError, zipfile.BadZipFile, OSError): the cache rebuilds the tree."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..core.validate import open_regular, read_npy
from ..model.scene import Scene
from .tree import Hierarchy, layout


def read_entry(entry: Path | BinaryIO, scene: Scene, rule: str) -> Hierarchy:
    """The hierarchy stored in `entry` (a path or an open binary file) for `scene` merged by `rule`, checked."""
    if isinstance(entry, Path):
        with open_regular(entry) as fh:
            return read_entry(fh, scene, rule)
    want = layout(scene)
    with zipfile.ZipFile(entry) as z:
        names = z.namelist()
        if sorted(names) != sorted(f"{name}.npy" for name in want):
            raise ValueError(f"members {names}, expected the arrays {sorted(want)}")
        arrays = {}
        for name, (shape, dtype) in want.items():
            with z.open(f"{name}.npy") as member:
                arrays[name] = read_npy(member, name, [shape], np.dtype(dtype))
    tree = Hierarchy(rule=rule, **arrays)
    tree.check(scene)
    return tree
