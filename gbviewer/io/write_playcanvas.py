"""Encoders of PlayCanvas's formats, the inverse of gbviewer.io.compressed_ply and gbviewer.io.sog (the layouts of
playcanvas/splat-transform src/lib/writers/write-compressed-ply.ts and write-sog.ts). Splats are written in Morton
order of their centres (as splat-transform does), so that each chunk or image row covers a small region; `order`
gives that permutation. Both stay in the scene's own frame.

Compressed `.ply` precision: per chunk of 256 splats, centres and log scales to 1/2047 (x, z) and 1/1023 (y) of the
chunk's range, half a step at most; colour (0.5 + SH_C0 dc) 8 bits of the chunk's range; opacity 0.5/255; rotation
smallest three of 10 bits in [-1/sqrt2, 1/sqrt2], sqrt2/2046 per component; SH bands 1-3 8 bits over [-4, 4]
(1/64; clamped there); the training mode as the `SplatRenderMode` comment.
`.sog` precision: centres 16 bits of each axis's range of sign(x) log(1 + |x|); log scales and DC: the nearest of
256 codebook entries (1-D k-means), half the widest gap between neighbouring entries at most; opacity 0.5/255;
rotation smallest three of 8 bits, (2/255)/sqrt2/2 per component; SH bands 1-3: each splat's own palette entry up
to 65536 splats, else a k-means palette of PALETTE entries, its values the nearest of 256 codebook entries;
`antialias` from the training mode.
"""

from __future__ import annotations

import io
import json
import math
import zipfile

import numpy as np
from PIL import Image

from ..model.scene import SH_C0, Scene
from .compressed_ply import CHUNK_SIZE, COLOR_PROPS, PACKED_PROPS, RANGE_PROPS
from .write import trained_as_comments
from .write_packed import antialiased_mode, u8

PALETTE = 4096  # SOG SH palette entries for scenes of more than 65536 splats
SAMPLE = 16  # splats per palette entry that the k-means rounds fit (then every splat takes its nearest entry)
KMEANS_ROUNDS = 6
SH_BANDS = {4: 1, 9: 2, 16: 3}


def order(scene: Scene) -> np.ndarray:
    """The splats' Morton order: centres quantised to 10 bits per axis of the scene's bounds, bits interleaved."""
    lo, hi = scene.means.min(axis=0), scene.means.max(axis=0)
    cells = np.clip((scene.means - lo) / np.where(hi > lo, hi - lo, 1) * 1023, 0, 1023).astype(np.uint64)
    code = np.zeros(scene.num_splats, np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cells[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


def _smallest_three(quats: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of each (w,x,y,z)'s largest component and the other three (in index order), the largest made >= 0."""
    q = quats.astype(np.float64)
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)[:, None]
    others = np.take_along_axis(q, np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[largest], axis=1)
    return largest, others


def _chunk_ranges(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-chunk float32 min and max of (N, 3) values and each value's fraction of its chunk's range."""
    n = len(v)
    pad = np.concatenate([v, np.repeat(v[-1:], -n % CHUNK_SIZE, axis=0)]).reshape(-1, CHUNK_SIZE, 3)
    lo, hi = pad.min(axis=1).astype(np.float32), pad.max(axis=1).astype(np.float32)
    lo_s = np.repeat(lo, CHUNK_SIZE, axis=0)[:n].astype(np.float64)
    span = np.repeat(hi, CHUNK_SIZE, axis=0)[:n].astype(np.float64) - lo_s
    return lo, hi, np.where(span > 0, (v - lo_s) / np.where(span > 0, span, 1), 0.0)


def _pack_fractions(t: np.ndarray) -> np.ndarray:
    bits = np.round(np.clip(t, 0, 1) * np.array([2047, 1023, 2047])).astype(np.uint32)
    return (bits[:, 0] << 21) | (bits[:, 1] << 11) | bits[:, 2]


def compressed_ply_bytes(scene: Scene) -> bytes:
    """A PlayCanvas compressed `.ply` (18-property chunks, an `sh` element with higher bands), Morton ordered."""
    s = _reordered(scene)
    n, k = s["means"].shape[0], s["sh"].shape[1]
    lo_p, hi_p, t_p = _chunk_ranges(s["means"].astype(np.float64))
    lo_s, hi_s, t_s = _chunk_ranges(np.log(s["scales"].astype(np.float64)))
    lo_c, hi_c, t_c = _chunk_ranges(0.5 + SH_C0 * s["sh"][:, 0].astype(np.float64))
    largest, others = _smallest_three(s["quats"])
    rot = largest.astype(np.uint32)
    for i in range(3):
        rot = (rot << 10) | np.round((others[:, i] / math.sqrt(2) + 0.5) * 1023).clip(0, 1023).astype(np.uint32)
    c8 = u8(t_c * 255).astype(np.uint32)
    color = (c8[:, 0] << 24) | (c8[:, 1] << 16) | (c8[:, 2] << 8) | u8(s["opacities"] * 255.0).astype(np.uint32)
    chunk = np.concatenate([lo_p, hi_p, lo_s, hi_s, lo_c, hi_c], axis=1).astype("<f4")
    header = ["ply", "format binary_little_endian 1.0"] + [f"comment {c}" for c in trained_as_comments(scene)]
    header += [f"element chunk {len(chunk)}"] + [f"property float {p}" for p in RANGE_PROPS + COLOR_PROPS]
    header += [f"element vertex {n}"] + [f"property uint {p}" for p in PACKED_PROPS]
    packed = np.stack([_pack_fractions(t_p), rot, _pack_fractions(t_s), color], axis=1).astype("<u4")
    body = chunk.tobytes() + packed.tobytes()
    if k > 1:
        rest = s["sh"][:, 1:].transpose(0, 2, 1).reshape(n, -1).astype(np.float64)  # channel-major
        header += [f"element sh {n}"] + [f"property uchar f_rest_{i}" for i in range(rest.shape[1])]
        body += u8((rest / 8 + 0.5) * 256 - 0.5).tobytes()
    return ("\n".join(header + ["end_header"]) + "\n").encode("ascii") + body


def _reordered(scene: Scene) -> dict[str, np.ndarray]:
    perm = order(scene)
    return {name: getattr(scene, name)[perm] for name in ("means", "scales", "quats", "opacities", "sh")}


def codebook(values: np.ndarray, size: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """1-D k-means of `values` into `size` sorted float32 entries (quantile start, Lloyd rounds; the ends pinned
    to the extremes, so every value lies between two entries) and each value's nearest entry."""
    v = np.asarray(values, np.float64).ravel()
    book = np.quantile(v, np.linspace(0, 1, size))
    for _ in range(KMEANS_ROUNDS):
        idx = _nearest(book, v)
        sums, counts = np.bincount(idx, v, size), np.bincount(idx, minlength=size)
        book = np.sort(np.where(counts > 0, sums / np.maximum(counts, 1), book))
        book[0], book[-1] = v.min(), v.max()
    book = np.sort(book.astype(np.float32))
    return book, _nearest(book.astype(np.float64), v)


def _nearest(book: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Index of the nearest entry of the sorted `book` for each value."""
    mids = (book[1:] + book[:-1]) / 2
    return np.searchsorted(mids, v)


def _webp(pixels: np.ndarray, width: int) -> bytes:
    """(N,4) uint8 pixels as a lossless RGBA WebP `width` wide (zero padded; RGB kept under zero alpha)."""
    rows = -(-len(pixels) // width)
    img = np.zeros((rows * width, 4), np.uint8)
    img[: len(pixels)] = pixels
    buf = io.BytesIO()
    Image.fromarray(img.reshape(rows, width, 4), "RGBA").save(buf, format="WEBP", lossless=True, exact=True)
    return buf.getvalue()


def _palette(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, K-1, 3) SH palette and each splat's label: the splats themselves up to 65536, else k-means (fitted on a
    random sample of SAMPLE splats per entry)."""
    n = len(rest)
    flat = rest.reshape(n, -1).astype(np.float32)
    if n <= 65536:
        return rest, np.arange(n)
    rng = np.random.default_rng(0)
    sample = flat[rng.choice(n, min(n, SAMPLE * PALETTE), replace=False)]
    centres = sample[:PALETTE]
    for _ in range(KMEANS_ROUNDS):
        labels = _assign(sample, centres)
        counts = np.bincount(labels, minlength=PALETTE)
        sums = np.zeros_like(centres, dtype=np.float64)
        np.add.at(sums, labels, sample)
        centres = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], centres).astype(np.float32)
    return centres.reshape(PALETTE, *rest.shape[1:]), _assign(flat, centres)


def _assign(flat: np.ndarray, centres: np.ndarray, rows: int = 2048) -> np.ndarray:
    """Nearest centre of each row (squared distances by matrix product, a block of rows at a time)."""
    norms = (centres * centres).sum(axis=1)
    return np.concatenate(
        [np.argmin(norms - 2 * flat[i : i + rows] @ centres.T, axis=1) for i in range(0, len(flat), rows)]
    )


def sog_bytes(scene: Scene) -> bytes:
    """A bundled `.sog` (zip of meta.json and lossless WebP images), Morton ordered."""
    s = _reordered(scene)
    n, k = s["means"].shape[0], s["sh"].shape[1]
    width = 4 * math.ceil(math.sqrt(n) / 4)
    opaque = np.full((n, 1), 255, np.uint8)
    means = s["means"].astype(np.float64)
    t = np.sign(means) * np.log1p(np.abs(means))
    mins, maxs = t.min(axis=0), t.max(axis=0)
    v = np.round((t - mins) / np.where(maxs > mins, maxs - mins, 1) * 65535).astype(np.uint16)
    largest, others = _smallest_three(s["quats"])
    quats = np.concatenate(
        [u8((others * math.sqrt(2) + 1) / 2 * 255), (252 + largest)[:, None].astype(np.uint8)], axis=1
    )
    s_book, s_idx = codebook(np.log(s["scales"].astype(np.float64)))
    c_book, c_idx = codebook(s["sh"][:, 0])
    files = {
        "means_l.webp": _webp(np.concatenate([(v & 255).astype(np.uint8), opaque], axis=1), width),
        "means_u.webp": _webp(np.concatenate([(v >> 8).astype(np.uint8), opaque], axis=1), width),
        "quats.webp": _webp(quats, width),
        "scales.webp": _webp(np.concatenate([s_idx.reshape(n, 3).astype(np.uint8), opaque], axis=1), width),
        "sh0.webp": _webp(
            np.concatenate([c_idx.reshape(n, 3).astype(np.uint8), u8(s["opacities"] * 255.0)[:, None]], axis=1), width
        ),
    }
    meta: dict = {
        "version": 2,
        "count": n,
        "antialias": antialiased_mode(scene),
        "means": {"mins": mins.tolist(), "maxs": maxs.tolist(), "files": ["means_l.webp", "means_u.webp"]},
        "scales": {"codebook": s_book.tolist(), "files": ["scales.webp"]},
        "quats": {"files": ["quats.webp"]},
        "sh0": {"codebook": c_book.tolist(), "files": ["sh0.webp"]},
    }
    if k > 1:
        palette, labels = _palette(s["sh"][:, 1:])
        p, coeffs = palette.shape[0], k - 1
        n_book, n_idx = codebook(palette)
        centroids = np.concatenate(
            [n_idx.reshape(p * coeffs, 3).astype(np.uint8), np.full((p * coeffs, 1), 255, np.uint8)], axis=1
        )
        lab = np.stack([labels & 255, labels >> 8, np.zeros(n, int), np.full(n, 255)], axis=1).astype(np.uint8)
        meta["shN"] = {
            "count": p,
            "bands": SH_BANDS[k],
            "codebook": n_book.tolist(),
            "files": ["shN_centroids.webp", "shN_labels.webp"],
        }
        files["shN_centroids.webp"] = _webp(centroids, 64 * coeffs)
        files["shN_labels.webp"] = _webp(lab, width)
    files["meta.json"] = json.dumps(meta).encode()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return buf.getvalue()
