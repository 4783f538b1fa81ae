"""Encoders of the byte-packed formats our readers decode (gbviewer.io.spz, gbviewer.io.splat), their inverse.

`.spz` (version 3, one gzip stream; nianticlabs/spz src/cc/load-spz.cc packGaussians): positions 24-bit fixed
point with F fractional bits (12, fewer where the scene reaches past 2^11, so that it fits) -> error <= 2^-(F+1);
alpha round(a * 255) -> 0.5/255; colour round(dc * 0.15 * 255 + 127.5) -> 0.5 / (0.15 * 255) in DC units, DC
clamped to [-3.33, 3.33]; scales round((log s + 10) * 16) -> 1/32 in log units, log s clamped to [-10, 5.94];
rotations smallest three with 9-bit magnitudes -> 2^-1 (1/sqrt2) / 511 per component; SH round(x * 128 + 128) ->
1/256, clamped to [-1, 127/128]; SH degree up to 3; the antialiased flag from the training mode.
`.splat` (antimatter15): positions and linear scales float32 (lossless); RGBA bytes -> 0.5/255 in colour
(0.5 + SH_C0 dc, clamped to [0, 1]) and opacity; quaternion round(q * 128 + 128) clamped -> 1/256 per
component; no higher SH bands.
"""

from __future__ import annotations

import gzip

import numpy as np

from ..model.scene import SH_C0, Scene
from .splat import RECORD
from .spz import COLOR_SCALE, FLIP_SH, FLIP_XYZ, LEGACY_HEADER, MAGIC
from .trained_as import ANTIALIASED, MIP_3D

SPZ_VERSION = 3
SPZ_FRACTIONAL_BITS = 12
SPZ_POSITION_LIMIT = 1 << 23  # 24-bit signed fixed point
SQRT_HALF = np.sqrt(0.5)


def u8(x: np.ndarray) -> np.ndarray:
    """Round to nearest and clamp to a byte."""
    return np.clip(np.round(np.nan_to_num(x)), 0, 255).astype(np.uint8)


def fractional_bits(means: np.ndarray) -> int:
    """The most fractional bits (at most 12) with which every coordinate fits SPZ's 24-bit fixed point."""
    reach = float(np.abs(means).max(initial=0.0))
    bits = SPZ_FRACTIONAL_BITS
    while bits > 0 and round(reach * (1 << bits)) >= SPZ_POSITION_LIMIT:
        bits -= 1
    return bits


def spz_bytes(
    means: np.ndarray, scales: np.ndarray, quats: np.ndarray, opacities: np.ndarray, sh: np.ndarray, antialiased: bool
) -> bytes:
    """A gzip SPZ v3 stream of splats given in the stream's own axes (quats (w,x,y,z))."""
    n, k = len(means), sh.shape[1]
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[k]
    bits = fractional_bits(means)
    fixed = np.round(means.astype(np.float64) * (1 << bits)).astype(np.int64) & 0xFFFFFF
    pos = np.stack([(fixed >> s) & 255 for s in (0, 8, 16)], axis=-1).astype(np.uint8)
    xyzw = np.concatenate([quats[:, 1:], quats[:, :1]], axis=1).astype(np.float64)
    xyzw /= np.maximum(np.linalg.norm(xyzw, axis=1, keepdims=True), 1e-30)
    largest = np.argmax(np.abs(xyzw), axis=1)
    xyzw *= np.where(xyzw[np.arange(n), largest] < 0, -1.0, 1.0)[:, None]
    comp = largest.astype(np.uint32)
    for i in range(4):  # the lowest index first, so it ends up in the highest bits
        field = ((xyzw[:, i] < 0).astype(np.uint32) << 9) | np.round(511 * np.abs(xyzw[:, i]) / SQRT_HALF).astype(
            np.uint32
        )
        comp = np.where(largest != i, (comp << 10) | field, comp)
    with np.errstate(divide="ignore"):
        log_scales = np.log(scales.astype(np.float64))
    rest = sh[:, 1:].astype(np.float64)  # coefficient-major, RGB inner
    header = LEGACY_HEADER.pack(MAGIC, SPZ_VERSION, n, degree, bits, 1 if antialiased else 0, 0)
    body = [
        pos,
        u8(opacities.astype(np.float64) * 255),
        u8(sh[:, 0].astype(np.float64) * COLOR_SCALE * 255 + 127.5),
        u8((log_scales + 10) * 16),
        comp.astype("<u4"),
        u8(rest * 128 + 128),
    ]
    return gzip.compress(header + b"".join(np.ascontiguousarray(a).tobytes() for a in body), compresslevel=6, mtime=0)


def encode_spz(scene: Scene) -> bytes:
    """A `.spz` file: the scene turned from the INRIA frame into SPZ's RUB (y and z negated)."""
    sh = np.array(scene.sh, np.float32)
    sh[:, 1:] *= FLIP_SH[: sh.shape[1] - 1, None]
    quats = scene.quats * np.concatenate([[1.0], FLIP_XYZ]).astype(np.float32)
    return spz_bytes(scene.means * FLIP_XYZ, scene.scales, quats, scene.opacities, sh, antialiased_mode(scene))


def antialiased_mode(scene: Scene) -> bool:
    """Whether the scene was trained antialiased (Mip-Splatting trains with its 2D filter too)."""
    return scene.meta.get("trained_as") in (ANTIALIASED, MIP_3D)


def encode_splat(scene: Scene) -> bytes:
    """A `.splat` file: 32-byte records in the scene's own frame."""
    rec = np.zeros(scene.num_splats, RECORD)
    rec["pos"], rec["scale"] = scene.means, scene.scales
    rec["rgba"][:, :3] = u8((0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64)) * 255)
    rec["rgba"][:, 3] = u8(scene.opacities.astype(np.float64) * 255)
    rec["rot"] = u8(scene.quats.astype(np.float64) * 128 + 128)
    return rec.tobytes()
