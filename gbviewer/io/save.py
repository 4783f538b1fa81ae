"""`save(scene, path)`: write a Scene in any format gbviewer reads, chosen by the file name (or `fmt`), atomically
and never over an existing file without `force`. Each encoder's module states its precision; `dropped` says in
one line what a format cannot hold of a given scene."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..core.errors import GBViewerError
from ..core.files import atomic_write
from ..model.scene import Scene
from .trained_as import UNKNOWN
from .write import refuse_neural, write_inria_ply
from .write_gltf import glb_bytes
from .write_packed import encode_splat, encode_spz
from .write_playcanvas import compressed_ply_bytes, sog_bytes

ENCODERS: dict[str, Callable[[Scene], bytes]] = {
    "compressed-ply": compressed_ply_bytes,
    "glb": glb_bytes,
    "glb-spz": lambda s: glb_bytes(s, spz=True),
    "spz": encode_spz,
    "splat": encode_splat,
    "sog": sog_bytes,
}
WRITE_FORMATS = ("ply", *ENCODERS)
# longest name endings first: "x.compressed.ply" is a compressed ply, "x.spz.glb" an SPZ-compressed glb
SUFFIXES = {
    ".compressed.ply": "compressed-ply",
    ".spz.glb": "glb-spz",
    ".ply": "ply",
    ".glb": "glb",
    ".spz": "spz",
    ".splat": "splat",
    ".sog": "sog",
}
CAN_SAY_TRAINED_AS = {"ply", "compressed-ply", "glb", "glb-spz", "spz", "sog"}


def format_for(path: str | Path, fmt: str | None = None) -> str:
    """The format `fmt` names, else the one `path`'s name ends in."""
    if fmt is not None:
        if fmt not in WRITE_FORMATS:
            raise GBViewerError(f"--format {fmt}; expected one of {', '.join(WRITE_FORMATS)}")
        return fmt
    name = Path(path).name.lower()
    for suffix, found in SUFFIXES.items():
        if name.endswith(suffix):
            return found
    raise GBViewerError(
        f"{path}: cannot tell the format from the name; expected a name ending in {', '.join(SUFFIXES)} (or --format)"
    )


def dropped(scene: Scene, fmt: str) -> str | None:
    """What writing `scene` as `fmt` loses beyond the format's quantisation, in one line (None: nothing)."""
    lost = []
    if fmt == "splat" and scene.sh.shape[1] > 1:
        lost.append(f"SH bands 1-{scene.sh_degree}")
    if fmt != "ply":
        if scene.filter_3d is not None:
            lost.append("the Mip-Splatting 3D filter (filter_3D)")
        if scene.oit is not None:
            lost.append("the sort-free / Duplex-GS data")
    if fmt not in CAN_SAY_TRAINED_AS and scene.meta.get("trained_as", UNKNOWN) != UNKNOWN:
        lost.append(f"the training mode ({scene.meta['trained_as']})")
    return f"{fmt} drops {', '.join(lost)}" if lost else None


def save(scene: Scene, path: str | Path, force: bool = False, fmt: str | None = None) -> Path:
    """Write `scene` to `path` in `fmt` or the format its name says (gbviewer.io.save.SUFFIXES)."""
    fmt = format_for(path, fmt)
    if fmt == "ply":
        return write_inria_ply(scene, path, force)
    refuse_neural(scene, fmt)
    data = ENCODERS[fmt](scene)
    return atomic_write(path, lambda tmp: tmp.write_bytes(data), force)
