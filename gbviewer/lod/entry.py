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

from ..scene import Scene
from ..validate import open_regular
from .tree import Hierarchy, layout

HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


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
                arrays[name] = _read_member(member, name, shape, np.dtype(dtype))
    tree = Hierarchy(rule=rule, **arrays)
    tree.check(scene)
    return tree


def _read_member(member: BinaryIO, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    """One .npy member: its header must say `dtype` and `shape` in C order, its data fill them exactly (the zip's
    CRC is checked at the member's end)."""
    version = np.lib.format.read_magic(member)
    if version not in HEADER_READERS:
        raise ValueError(f"{name}: .npy format version {version}, expected 1.0 or 2.0")
    got_shape, fortran, got_dtype = HEADER_READERS[version](member, max_header_size=1 << 12)
    if got_shape != shape or got_dtype != dtype or fortran:
        raise ValueError(f"{name} is {got_dtype} {got_shape}{' (Fortran order)' if fortran else ''}, expected "
                         f"{dtype} {shape}")
    out = np.empty(shape, dtype)
    buf = memoryview(out.reshape(-1).view(np.uint8))
    got = 0
    while got < len(buf):
        n = member.readinto(buf[got:])
        if not n:
            raise ValueError(f"{name}: data ends after {got} of {len(buf)} bytes")
        got += n
    if member.read(1):
        raise ValueError(f"{name}: data runs past its {len(buf)} bytes")
    return out
