"""Real-size test scenes: a shared capture tiled N times on a grid in its ground plane, SH padded to degree 3, written
as an INRIA `.ply` to the user cache folder (never the repository) and reused while its recorded parameters match.

The file is deterministic (same source and tile count: the same bytes; its SHA-256 is recorded beside it) and
written tile by tile, so building it needs memory for one tile only. Tile t sits at grid cell (t % cols, t // cols)
of a square-ish grid, offset by 1.1 times the source's extent along x and z; every tile holds the source's splats
in its order, so `scene[t * n + i]` is splat i of the source moved by tile t's offset.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from ..core.files import atomic_write
from ..io import load
from ..io.write import inria_columns, ply_header
from ..model.scene import Scene

VERSION = 1  # bump when the layout of the file changes
SPACING = 1.1  # grid step in units of the source's extent
TILES = {"1m": 7, "6m": 40}  # of biker.compressed.ply (152,746 splats): 1,069,222 and 6,109,840 splats


def cache_dir() -> Path:
    """The user cache folder of these scenes (platformdirs: ~/.cache/gbviewer/scale on Linux)."""
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("gbviewer", appauthor=False)) / "scale"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 24):
            h.update(chunk)
    return h.hexdigest()


def padded(scene: Scene, degree: int = 3) -> Scene:
    """`scene` with its SH padded with zero coefficients up to `degree` (unchanged if it has them)."""
    k = (degree + 1) ** 2
    if scene.sh.shape[1] >= k:
        return scene
    sh = np.zeros((scene.num_splats, k, 3), np.float32)
    sh[:, : scene.sh.shape[1]] = scene.sh
    return Scene.from_arrays(
        scene.means,
        scene.scales,
        scene.quats,
        scene.opacities,
        sh,
        scene.filter_3d,
        source=scene.source,
        meta=scene.meta,
    )


def grid_offsets(scene: Scene, tiles: int) -> np.ndarray:
    """(tiles, 3) float32 offsets of the tiles: a ceil(sqrt(tiles))-wide grid in the x-z plane."""
    lo, hi = scene.bounds
    step = SPACING * (hi - lo).astype(np.float64)
    cols = math.ceil(math.sqrt(tiles))
    t = np.arange(tiles)
    return np.stack([(t % cols) * step[0], np.zeros(tiles), (t // cols) * step[2]], axis=1).astype(np.float32)


def write_tiled(scene: Scene, tiles: int, path: Path) -> str:
    """Write `scene` tiled `tiles` times (see `grid_offsets`) to `path` atomically, one tile at a time; returns the
    file's SHA-256."""
    cols = inria_columns(scene)
    names = list(cols)
    body = np.stack(list(cols.values()), axis=1).astype("<f4")  # one tile's rows
    xyz = [names.index(c) for c in "xyz"]
    offsets = grid_offsets(scene, tiles)
    header = ply_header(scene.num_splats * tiles, names)
    digest = hashlib.sha256(header)

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(header)
            tile = np.empty_like(body)
            for off in offsets:
                tile[:] = body
                tile[:, xyz] += off
                data = tile.tobytes()
                digest.update(data)
                fh.write(data)

    atomic_write(path, write, force=True)
    return digest.hexdigest()


def tiled_scene(tiles: int, source: Path, folder: Path | None = None, verify: bool = False, log=print) -> Path:
    """The path of `source` tiled `tiles` times with SH degree 3 in `folder` (default `cache_dir()`): reused when
    its record (source hash, tiles, version, size; with `verify` also the file's own hash) matches, else built."""
    source = Path(source)
    folder = Path(folder) if folder is not None else cache_dir()
    path = folder / f"{source.name.split('.')[0]}-x{tiles}.ply"
    record_path = path.with_suffix(".json")
    params = {
        "source": source.name,
        "source_sha256": _sha256(source),
        "tiles": tiles,
        "version": VERSION,
        "sh_degree": 3,
    }
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError):
        record = None
    if (
        isinstance(record, dict)
        and record.get("params") == params
        and path.is_file()
        and path.stat().st_size == record.get("bytes")
        and (not verify or _sha256(path) == record.get("sha256"))
    ):
        return path
    base = padded(load(source))
    log(f"building {path} ({base.num_splats * tiles:,} splats) ...")
    digest = write_tiled(base, tiles, path)
    record = {"params": params, "splats": base.num_splats * tiles, "bytes": path.stat().st_size, "sha256": digest}
    atomic_write(record_path, lambda tmp: tmp.write_text(json.dumps(record, indent=1) + "\n"), force=True)
    return path
