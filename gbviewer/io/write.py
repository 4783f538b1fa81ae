"""Write a Scene as a standard INRIA 3DGS `.ply` (binary float32, KERNELS.md §1.1).

Raw parameters are chosen so that loading the file gives back the Scene bit for bit whenever such
values exist (always for a Scene loaded from an INRIA `.ply`): log and logit are refined by whole
float32 steps until exp and sigmoid reproduce the stored values, and each unit quaternion is given
a scale that normalises back to itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..figure import atomic_write
from ..scene import Scene
from .ply import activate_opacity, activate_scales

RAW_LIMIT = 110.0  # |logit| and |log| beyond this saturate float32 sigmoid and exp
MAX_STEPS = 16
QUAT_SCALES = [1.0] + [1.0 + s * k * 2.0 ** -24 for k in range(1, 9) for s in (1, -1)]


def _invert(activate, guess: np.ndarray, target: np.ndarray) -> np.ndarray:
    """float32 raw values with activate(raw) == target, stepping the initial guess by ulps where needed."""
    raw = np.clip(np.nan_to_num(guess, nan=0.0), -RAW_LIMIT, RAW_LIMIT).astype(np.float32)
    for _ in range(MAX_STEPS):
        got = activate(raw)
        bad = got != target
        if not bad.any():
            break
        raw[bad] = np.nextafter(raw[bad], np.where(got[bad] < target[bad], np.float32(np.inf), np.float32(-np.inf)))
    return raw


def _normalise(q: np.ndarray) -> np.ndarray:
    """The loader's quaternion normalisation (Scene.from_arrays)."""
    return q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)


def _quat_preimage(quats: np.ndarray) -> np.ndarray:
    """Quaternions that normalise back to exactly `quats` (falls back to `quats` itself)."""
    out = quats.copy()
    todo = np.flatnonzero((_normalise(quats) != quats).any(axis=1))
    for s in QUAT_SCALES[1:]:
        if todo.size == 0:
            break
        cand = (quats[todo].astype(np.float64) * s).astype(np.float32)
        ok = (_normalise(cand) == quats[todo]).all(axis=1)
        out[todo[ok]] = cand[ok]
        todo = todo[~ok]
    return out


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
    cols.update({f"scale_{i}": scale[:, i] for i in range(3)})
    quats = _quat_preimage(scene.quats)
    cols.update({f"rot_{i}": quats[:, i] for i in range(4)})
    if scene.filter_3d is not None:
        cols["filter_3D"] = scene.filter_3d
    return cols


def write_inria_ply(scene: Scene, path: str | Path, force: bool = False) -> Path:
    """Write `scene` to `path` atomically; refuses to overwrite an existing file unless `force`."""
    cols = inria_columns(scene)
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {scene.num_splats}\n"
              + "".join(f"property float {name}\n" for name in cols) + "end_header\n").encode("ascii")
    body = np.stack(list(cols.values()), axis=1).astype("<f4")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(body.tobytes())

    return atomic_write(path, write, force)
