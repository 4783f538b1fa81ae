"""Small vectorised encoders for every format the loaders read, written from the format descriptions.

Inputs are activated values in the INRIA/COLMAP frame: means (N,3), scales (N,3) > 0, quats (N,4) as
(w,x,y,z), opacities (N,) in [0,1], sh (N,K,3) with DC first. Independent of the loaders (the decoder tests hold
the loaders to them); also used by bench/load_speed.py and for the fuzzing seeds in tests/io/fuzz/seeds.
"""

from __future__ import annotations

import gzip
import io
import json
import math
import struct
import zipfile
from pathlib import Path

import numpy as np
import zstandard
from PIL import Image

from gbviewer.model.scene import SH_C0

FLIP_XYZ = np.array([1.0, -1.0, -1.0])
FLIP_SH = np.array([-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1], dtype=np.float64)


def random_params(n: int, sh_degree: int = 0, seed: int = 0) -> dict[str, np.ndarray]:
    """Random activated splat parameters of a plausible range."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return {
        "means": rng.uniform(-3, 3, (n, 3)),
        "scales": np.exp(rng.uniform(-7, 0, (n, 3))),
        "quats": q / np.linalg.norm(q, axis=1, keepdims=True),
        "opacities": rng.uniform(0.01, 0.99, n),
        "sh": np.concatenate(
            [rng.uniform(-1.5, 1.5, (n, 1, 3)), rng.uniform(-0.6, 0.6, (n, (sh_degree + 1) ** 2 - 1, 3))], axis=1
        ),
    }


def _u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x), 0, 255).astype(np.uint8)


def encode_splat(s: dict) -> bytes:
    rec = np.zeros(len(s["means"]), dtype=[("pos", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rot", "u1", 4)])
    rec["pos"], rec["scale"] = s["means"], s["scales"]
    rec["rgba"][:, :3] = _u8((0.5 + SH_C0 * s["sh"][:, 0]) * 255)
    rec["rgba"][:, 3] = _u8(s["opacities"] * 255)
    rec["rot"] = _u8(s["quats"] * 128 + 128)
    return rec.tobytes()


def _smallest_three_spz(q_xyzw: np.ndarray) -> np.ndarray:
    """SPZ v3 packing: 2-bit largest index, then sign + 9-bit magnitude per other component."""
    largest = np.argmax(np.abs(q_xyzw), axis=1)
    q = q_xyzw * np.where(q_xyzw[np.arange(len(q_xyzw)), largest] < 0, -1.0, 1.0)[:, None]
    comp = largest.astype(np.uint32)
    for i in range(4):
        keep = largest != i
        mag = np.round(511 * np.abs(q[:, i]) / math.sqrt(0.5)).astype(np.uint32)
        field = ((q[:, i] < 0).astype(np.uint32) << 9) | mag
        comp = np.where(keep, (comp << 10) | field, comp)
    return comp.astype("<u4")


def spz_arrays(s: dict, version: int, frac_bits: int = 12) -> list[bytes]:
    """Attribute arrays (positions, alphas, colours, scales, rotations, sh) as the packer writes them."""
    p = s["means"] * FLIP_XYZ  # RDF -> RUB
    if version == 1:
        pos = p.astype("<f2").tobytes()
    else:
        fixed = np.round(p * (1 << frac_bits)).astype(np.int64) & 0xFFFFFF
        pos = np.stack([(fixed >> k) & 255 for k in (0, 8, 16)], axis=-1).astype(np.uint8).tobytes()
    xyzw = np.concatenate([s["quats"][:, 1:] * FLIP_XYZ, s["quats"][:, :1]], axis=1)
    if version >= 3:
        rot = _smallest_three_spz(xyzw).tobytes()
    else:
        xyzw = xyzw * np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
        rot = _u8(xyzw[:, :3] * 127.5 + 127.5).tobytes()
    flips = np.concatenate([FLIP_SH, np.ones(9)])  # degree-4 signs are not needed by the tests
    rest = s["sh"][:, 1:] * flips[: s["sh"].shape[1] - 1, None]
    return [
        pos,
        _u8(s["opacities"] * 255).tobytes(),
        _u8(s["sh"][:, 0] * 0.15 * 255 + 127.5).tobytes(),
        _u8((np.log(s["scales"]) + 10) * 16).tobytes(),
        rot,
        _u8(rest * 128 + 128).tobytes(),
    ]


def encode_spz(
    s: dict,
    version: int = 3,
    frac_bits: int = 12,
    extensions: bytes = b"",
    gzipped: bool = True,
    antialiased: bool = False,
) -> bytes:
    """A complete .spz file: gzip (or raw) legacy stream for v1-3, NGSP container with zstd for v4."""
    n, degree = len(s["means"]), int(round(math.sqrt(s["sh"].shape[1]))) - 1
    arrays = spz_arrays(s, version, frac_bits)
    flags = (1 if antialiased else 0) | (2 if extensions else 0)
    if version < 4:
        raw = struct.pack("<4sIIBBBB", b"NGSP", version, n, degree, frac_bits, flags, 0) + extensions
        raw += b"".join(arrays)
        return gzip.compress(raw) if gzipped else raw
    streams = [zstandard.ZstdCompressor(level=3).compress(a) for a in arrays if a]
    sizes = [len(a) for a in arrays if a]
    head = struct.pack("<4sIIBBBBI12x", b"NGSP", 4, n, degree, frac_bits, flags, len(streams), 32 + len(extensions))
    toc = b"".join(struct.pack("<QQ", len(c), u) for c, u in zip(streams, sizes))
    return head + extensions + toc + b"".join(streams)


def _pack_fractions(t: np.ndarray) -> np.ndarray:
    """(N,3) fractions in [0,1] as 11/10/11-bit uint32."""
    bits = np.round(np.clip(t, 0, 1) * np.array([2047, 1023, 2047])).astype(np.uint32)
    return (bits[:, 0] << 21) | (bits[:, 1] << 11) | bits[:, 2]


def _chunk_fractions(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-256-splat min, max and the fraction of each value within its chunk's range."""
    n = len(v)
    pad = np.concatenate([v, np.repeat(v[-1:], (-n) % 256, axis=0)]).reshape(-1, 256, v.shape[1])
    lo, hi = pad.min(axis=1), pad.max(axis=1)
    lo_s, hi_s = np.repeat(lo, 256, axis=0)[:n], np.repeat(hi, 256, axis=0)[:n]
    return lo, hi, np.where(hi_s > lo_s, (v - lo_s) / np.where(hi_s > lo_s, hi_s - lo_s, 1), 0)


def compressed_ply_columns(s: dict, color_ranges: bool = True):
    """Chunk table (C, 12 or 18) float32 and the four packed uint32 vertex columns."""
    lo_p, hi_p, t_p = _chunk_fractions(s["means"])
    lo_s, hi_s, t_s = _chunk_fractions(np.log(s["scales"]))
    rgb = 0.5 + SH_C0 * s["sh"][:, 0]
    chunks = [lo_p, hi_p, lo_s, hi_s]
    if color_ranges:
        lo_c, hi_c, t_c = _chunk_fractions(rgb)
        chunks += [lo_c, hi_c]
    else:
        t_c = rgb
    q = s["quats"]
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)[:, None]
    rot = largest.astype(np.uint32)
    for i in range(4):
        v = np.round((q[:, i] / math.sqrt(2) + 0.5) * 1023).astype(np.uint32)
        rot = np.where(largest != i, (rot << 10) | v, rot)
    c8 = _u8(np.clip(t_c, 0, 1) * 255).astype(np.uint32)
    color = (c8[:, 0] << 24) | (c8[:, 1] << 16) | (c8[:, 2] << 8) | _u8(s["opacities"] * 255).astype(np.uint32)
    return np.concatenate(chunks, axis=1).astype("<f4"), [_pack_fractions(t_p), rot, _pack_fractions(t_s), color]


def encode_compressed_ply(s: dict, color_ranges: bool = True) -> bytes:
    """A SuperSplat compressed .ply, with an `sh` element when s has higher bands."""
    n, k = len(s["means"]), s["sh"].shape[1]
    chunk, packed = compressed_ply_columns(s, color_ranges)
    names = [
        "min_x",
        "min_y",
        "min_z",
        "max_x",
        "max_y",
        "max_z",
        "min_scale_x",
        "min_scale_y",
        "min_scale_z",
        "max_scale_x",
        "max_scale_y",
        "max_scale_z",
    ] + (["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"] if color_ranges else [])
    header = ["ply", "format binary_little_endian 1.0", f"element chunk {len(chunk)}"]
    header += [f"property float {p}" for p in names]
    header += [f"element vertex {n}"] + [
        f"property uint {p}" for p in ("packed_position", "packed_rotation", "packed_scale", "packed_color")
    ]
    body = chunk.tobytes() + np.stack(packed, axis=1).astype("<u4").tobytes()
    if k > 1:
        rest = s["sh"][:, 1:].transpose(0, 2, 1).reshape(n, -1)  # channel-major
        header += [f"element sh {n}"] + [f"property uchar f_rest_{i}" for i in range(rest.shape[1])]
        body += _u8((rest / 8 + 0.5) * 256 - 0.5).tobytes()
    return ("\n".join(header + ["end_header"]) + "\n").encode() + body


def _webp(pixels: np.ndarray, width: int) -> bytes:
    """(N,4) uint8 pixels as a lossless RGBA WebP `width` wide (padded with zeros)."""
    h = -(-len(pixels) // width)
    img = np.zeros((h * width, 4), np.uint8)
    img[: len(pixels)] = pixels
    buf = io.BytesIO()
    Image.fromarray(img.reshape(h, width, 4), "RGBA").save(
        buf, format="WEBP", lossless=True, exact=True, quality=0, method=0
    )
    return buf.getvalue()


def sog_files(s: dict, palette: np.ndarray | None = None, labels: np.ndarray | None = None) -> dict[str, bytes]:
    """meta.json and images of a SOG v2 scene. With SH bands, pass the palette (P,K-1,3) and labels (N,)."""
    n = len(s["means"])
    width = max(1, math.ceil(math.sqrt(n)))
    t = np.sign(s["means"]) * np.log1p(np.abs(s["means"]))
    mins, maxs = t.min(axis=0), t.max(axis=0)
    v = np.round((t - mins) / np.where(maxs > mins, maxs - mins, 1) * 65535).astype(np.uint16)
    full = np.full((n, 1), 255, np.uint8)
    lo = np.concatenate([(v & 255).astype(np.uint8), full], axis=1)
    hi = np.concatenate([(v >> 8).astype(np.uint8), full], axis=1)
    q = s["quats"]
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(n), largest] < 0, -1.0, 1.0)[:, None]
    others = np.take_along_axis(q, np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[largest], axis=1)
    quats = np.concatenate(
        [_u8((others * math.sqrt(2) + 1) / 2 * 255), (252 + largest)[:, None].astype(np.uint8)], axis=1
    )
    log_s = np.log(s["scales"])
    s_book = np.linspace(log_s.min(), log_s.max(), 256)
    dc = s["sh"][:, 0]
    c_book = np.linspace(dc.min(), dc.max(), 256)
    scales = np.concatenate([_nearest(s_book, log_s), full], axis=1)
    sh0 = np.concatenate([_nearest(c_book, dc), _u8(s["opacities"] * 255)[:, None]], axis=1)
    meta = {
        "version": 2,
        "count": n,
        "means": {"mins": mins.tolist(), "maxs": maxs.tolist(), "files": ["means_l.webp", "means_u.webp"]},
        "scales": {"codebook": s_book.tolist(), "files": ["scales.webp"]},
        "quats": {"files": ["quats.webp"]},
        "sh0": {"codebook": c_book.tolist(), "files": ["sh0.webp"]},
    }
    files = {
        "means_l.webp": _webp(lo, width),
        "means_u.webp": _webp(hi, width),
        "quats.webp": _webp(quats, width),
        "scales.webp": _webp(scales, width),
        "sh0.webp": _webp(sh0, width),
    }
    if palette is not None:
        p, k = palette.shape[0], palette.shape[1]
        n_book = np.linspace(palette.min(), palette.max(), 256)
        centroids = np.concatenate(
            [_nearest(n_book, palette.reshape(-1, 3)), np.full((p * k, 1), 255, np.uint8)], axis=1
        )
        lab = np.stack([labels & 255, labels >> 8, np.zeros(n, int), np.full(n, 255)], axis=1).astype(np.uint8)
        meta["shN"] = {
            "count": p,
            "bands": {3: 1, 8: 2, 15: 3}[k],
            "codebook": n_book.tolist(),
            "files": ["shN_centroids.webp", "shN_labels.webp"],
        }
        files["shN_centroids.webp"] = _webp(centroids, 64 * k)
        files["shN_labels.webp"] = _webp(lab, width)
    files["meta.json"] = json.dumps(meta).encode()
    return files


def _nearest(book: np.ndarray, values: np.ndarray) -> np.ndarray:
    step = (book[-1] - book[0]) / 255 if book[-1] > book[0] else 1.0
    return np.clip(np.round((values - book[0]) / step), 0, 255).astype(np.uint8)


def write_sog(files: dict[str, bytes], path: Path, bundled: bool = True) -> Path:
    """Write SOG files as a .sog zip or into a folder."""
    if bundled:
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
            for name, data in files.items():
                zf.writestr(name, data)
    else:
        path.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            (path / name).write_bytes(data)
    return path
