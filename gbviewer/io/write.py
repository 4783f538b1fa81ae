"""Write a Scene as a standard INRIA 3DGS `.ply` (binary float32, docs/formats.md#inria-3dgs-ply).

Raw parameters are chosen so that loading the file gives back the Scene bit for bit whenever such
values exist (always for a Scene loaded from an INRIA `.ply`): log and logit are refined, by
bisection over float32 values, until exp and sigmoid reproduce the stored values. Quaternions are
written as stored; being unit, `Scene.from_arrays` keeps them unchanged.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import GBViewerError
from ..core.files import atomic_write
from ..model.scene import Scene
from .ply import activate_opacity, activate_scales
from .trained_as import COMMENT_KEY, WRITTEN

RAW_LIMIT = 110.0  # |logit| and |log| beyond this saturate float32 sigmoid and exp
SEARCH_ULPS = 1 << 16  # how far (in float32 steps) the exact preimage may lie from the float64 inverse
NEIGHBOURS = 8  # float32 steps scanned around the bisection result


def _key(x: np.ndarray) -> np.ndarray:
    """float32 -> int64 keys ordered like the floats (adjacent floats have adjacent keys)."""
    i = x.astype(np.float32).view(np.int32).astype(np.int64)
    return np.where(i < 0, -(i & 0x7FFFFFFF), i)


def _unkey(k: np.ndarray) -> np.ndarray:
    return np.where(k < 0, (-k) | 0x80000000, k).astype(np.uint32).view(np.float32)


def _invert(activate, guess: np.ndarray, target: np.ndarray) -> np.ndarray:
    """float32 raw with activate(raw) == target: bisection around the float64 guess, then a local scan."""
    raw = np.clip(np.nan_to_num(guess, nan=0.0), -RAW_LIMIT, RAW_LIMIT).astype(np.float32).ravel()
    want = np.asarray(target, np.float32).ravel()
    bad = np.flatnonzero(activate(raw) != want)
    if bad.size:
        lo = _key(raw[bad]) - SEARCH_ULPS
        hi = lo + 2 * SEARCH_ULPS
        while (hi - lo > 1).any():  # the first float with activate(raw) >= want
            mid = (lo + hi) // 2
            below = activate(_unkey(mid)) < want[bad]
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        best = _unkey(hi)
        found = activate(best) == want[bad]
        for step in range(-NEIGHBOURS, NEIGHBOURS + 1):  # numpy's float32 exp is monotone only within an ulp
            cand = _unkey(hi + step)
            hit = ~found & (activate(cand) == want[bad])
            best[hit], found = cand[hit], found | hit
        raw[bad] = best
    return raw.reshape(np.shape(target))


def inria_columns(scene: Scene) -> dict[str, np.ndarray]:
    """Raw INRIA vertex properties, in the standard order, for a Scene."""
    n, k = scene.num_splats, scene.sh.shape[1]
    with np.errstate(divide="ignore"):
        op = scene.opacities.astype(np.float64)
        opacity = _invert(activate_opacity, np.log(op) - np.log1p(-op), scene.opacities)
        scale = _invert(activate_scales, np.log(scene.scales.astype(np.float64)), scene.scales)
    cols = {name: scene.means[:, i] for i, name in enumerate("xyz")}
    cols.update({name: np.zeros(n, np.float32) for name in ("nx", "ny", "nz")})
    cols.update({f"f_dc_{c}": scene.sh[:, 0, c] for c in range(3)})
    rest = scene.sh[:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))  # channel-major
    cols.update({f"f_rest_{i}": rest[:, i] for i in range(rest.shape[1])})
    cols["opacity"] = opacity
    oit = scene.oit
    vw = oit.view_weight_sh if oit is not None else None
    if vw is not None:  # sort-free GS layout (docs/formats.md#variant-layouts)
        cols["f_do_0"] = vw[:, 0]
        cols.update({f"f_ro_{i}": vw[:, i + 1] for i in range(vw.shape[1] - 1)})
    cols.update({f"scale_{i}": scale[:, i] for i in range(3)})
    cols.update({f"rot_{i}": scene.quats[:, i] for i in range(4)})  # unit, so loading keeps them as they are
    if scene.filter_3d is not None:
        cols["filter_3D"] = scene.filter_3d
    if vw is not None:
        info = np.zeros(n, np.float32)
        info[0] = oit.weight_background if oit.weight_background is not None else 0.02
        if n > 1:
            info[1] = oit.sigma if oit.sigma is not None else 10.0
        cols["info"] = info
    return cols


def ply_header(n: int, names: list[str], comments: tuple[str, ...] = ()) -> bytes:
    """The header of a binary little-endian PLY with `n` vertices of float32 properties `names`."""
    return (
        "ply\nformat binary_little_endian 1.0\n"
        + "".join(f"comment {c}\n" for c in comments)
        + f"element vertex {n}\n"
        + "".join(f"property float {name}\n" for name in names)
        + "end_header\n"
    ).encode("ascii")


def trained_as_comments(scene: Scene) -> tuple[str, ...]:
    """The `SplatRenderMode` comment that keeps the scene's known training mode (gbviewer.io.trained_as)."""
    value = WRITTEN.get(scene.meta.get("trained_as", ""))
    return (f"{COMMENT_KEY}: {value}",) if value else ()


def refuse_neural(scene: Scene, what: str) -> None:
    """Refuse a Duplex-GS checkpoint, whose splats only its MLPs give, per view."""
    if scene.oit is not None and scene.oit.neural is not None:
        raise GBViewerError(
            f"{scene.source}: a Duplex-GS checkpoint has no fixed splats (its MLPs decode them per "
            f"view), so it cannot be written as {what}"
        )


def write_inria_ply(scene: Scene, path: str | Path, force: bool = False) -> Path:
    """Write `scene` to `path` atomically, its known training mode as a `SplatRenderMode` comment; refuses to
    overwrite an existing file unless `force`."""
    refuse_neural(scene, "an INRIA ply")
    cols = inria_columns(scene)
    header = ply_header(scene.num_splats, list(cols), trained_as_comments(scene))
    body = np.stack(list(cols.values()), axis=1).astype("<f4")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(body.tobytes())

    return atomic_write(path, write, force)
