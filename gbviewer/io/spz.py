"""Niantic `.spz`: versions 1-3 (one gzip stream) and 4 (NGSP container of zstd streams).

Legacy files gzip a 16-byte header (magic NGSP, version, count, SH degree, fractional bits, flags,
reserved), optional extension records (flag 0x2), then the attribute arrays. Version 4 keeps a
32-byte plain header (plus stream count and TOC offset), extension records up to the TOC, a TOC of
(compressed, uncompressed) uint64 sizes and one zstd stream per attribute.
Attributes, in order: positions (24-bit fixed point; float16 in v1), alphas (sigmoid * 255),
colours (dc * 0.15 * 255 + 127.5), scales ((log + 10) * 16), rotations (v1-2: xyz bytes, w >= 0;
v3+: smallest three, 2-bit index + 3 x (sign + 9 bits)), SH (coefficient-major, RGB inner,
(v - 128) / 128). Data is stored right-up-back (RUB); we convert to the INRIA/COLMAP right-down-front
frame as the reference library does for PLY export: negate y and z, the quaternion's y and z, and
the SH coefficients that are odd in y or z.
"""

from __future__ import annotations

import itertools
import struct
import warnings
import zlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import zstandard

from ..core.errors import SceneFormatError
from ..model.scene import Scene
from .packing import MAX_SPLATS, smallest_three
from .progress import LoadProgress, decode_in_chunks

MAGIC = b"NGSP"
GZIP_MAGIC = b"\x1f\x8b"
LEGACY_HEADER = struct.Struct("<4sIIBBBB")  # 16 bytes
NGSP_HEADER = struct.Struct("<4sIIBBBBI12x")  # 32 bytes
TOC_ENTRY = struct.Struct("<QQ")
EXTENSIONS_FLAG = 0x2
ANTIALIASED_FLAG = 0x1
MAX_EXTENSION_BYTES = 1 << 20  # extension records allowed ahead of the legacy attribute arrays
MAX_COMPRESSION_RATIO = 64  # declared attribute bytes per compressed byte: real splat data compresses < 4x, so a
# larger claim is a corrupt or hostile header (the reference loader allows 1024, which lets 1.6 MB inflate to 1.6 GB)
SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}
COLOR_SCALE = 0.15
FLIP_XYZ = np.array([1.0, -1.0, -1.0], dtype=np.float32)  # RUB -> RDF, for positions and quaternion xyz
# Sign of each SH coefficient (degree 1..3, 3DGS basis order) under (x, y, z) -> (x, -y, -z).
FLIP_SH = np.array([-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1], dtype=np.float32)


def _sizes(version: int, n: int, sh_degree: int) -> dict[str, int]:
    """Byte size of each attribute array, in file order."""
    return {
        "positions": n * (6 if version == 1 else 9),
        "alphas": n,
        "colors": 3 * n,
        "scales": 3 * n,
        "rotations": n * (4 if version >= 3 else 3),
        "sh": n * SH_DIM[sh_degree] * 3,
    }


def _check_ratio(path: Path, declared: int, compressed: int) -> None:
    """Refuse, before inflating anything, a header whose attribute bytes the compressed bytes cannot plausibly hold."""
    if declared > MAX_COMPRESSION_RATIO * compressed:
        raise SceneFormatError(
            path,
            f"{declared} bytes of attributes cannot come from {compressed} compressed bytes "
            f"(more than {MAX_COMPRESSION_RATIO}x); corrupt header",
            field="numPoints",
        )


def _check_header(path: Path, version: int, n: int, sh_degree: int, known: range) -> None:
    if version not in known:
        raise SceneFormatError(path, f"unknown spz version {version}; supported: 1-4", field="version")
    if sh_degree not in SH_DIM:
        raise SceneFormatError(path, f"SH degree {sh_degree}; expected 0-4", field="shDegree")
    if not 0 < n <= MAX_SPLATS:
        raise SceneFormatError(path, f"splat count {n}; expected 1..{MAX_SPLATS}", field="numPoints")


def read_spz(path: Path, progress: LoadProgress) -> Scene:
    """An `.spz` file: a gzip one is read and inflated in one pass (progress: its bytes), the others read whole."""
    with open(path, "rb") as fh:
        size = fh.seek(0, 2) - fh.seek(0)
        if fh.read(2) != GZIP_MAGIC:
            fh.seek(0)
            return load_spz(path, progress.read(fh, size), progress)
        fh.seek(0)
        payload = _gunzip(path, progress.pieces(fh, size), size)
    progress.report(size, size, "bytes")
    return _load_legacy(path, payload, "gzip", progress)


def load_spz(path: Path, data: bytes | bytearray, progress: LoadProgress | None = None) -> Scene:
    """Decode any supported `.spz` buffer (gzip legacy, raw legacy or NGSP v4) into a Scene; `progress`: splats
    decoded."""
    progress = progress or LoadProgress()
    if data[:2] == GZIP_MAGIC:
        return _load_legacy(path, _gunzip(path, [data], len(data)), "gzip", progress)
    if len(data) >= 8 and data[:4] == MAGIC and struct.unpack_from("<I", data, 4)[0] >= 4:
        return _load_ngsp(path, data, progress)
    return _load_legacy(path, data, "raw", progress)


def _gunzip(path: Path, pieces: Iterable[bytes], compressed: int) -> bytes:
    """Inflate the legacy stream, given in `pieces` (`compressed` bytes in all), stopping once the header's count
    of attribute bytes is reached."""
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    out = bytearray()
    limit = 0  # the output wanted: the header until it is read, then the header and its attribute bytes
    try:
        for piece in itertools.chain(pieces, [b""]):  # b"": what zlib still holds once the input is all given
            while not d.eof:
                want = limit or LEGACY_HEADER.size
                out += d.decompress(piece, want - len(out))
                piece = d.unconsumed_tail
                if len(out) == want:
                    if limit:
                        return bytes(out)
                    limit = _gzip_limit(path, out, compressed)
                elif not piece:
                    break  # all of this piece inflated: the next one
    except zlib.error as exc:
        raise SceneFormatError(path, f"corrupt gzip stream: {exc}", field="gzip") from None
    if not limit:
        raise SceneFormatError(path, "gzip stream ends inside the 16-byte header", field="header")
    if not d.eof:
        raise SceneFormatError(path, "truncated gzip stream (no end-of-stream marker)", field="gzip")
    return bytes(out)


def _gzip_limit(path: Path, head: bytes | bytearray, compressed: int) -> int:
    """Payload bytes to inflate at most, from the legacy header (refused before inflating more when it is corrupt
    or claims more than `compressed` bytes can hold)."""
    magic, version, n, sh_degree, _, _, _ = LEGACY_HEADER.unpack_from(head)
    if magic != MAGIC:
        raise SceneFormatError(path, f"gzip data does not start with NGSP (got {magic!r})", field="magic")
    _check_header(path, version, n, sh_degree, range(1, 4))
    declared = sum(_sizes(version, n, sh_degree).values())
    _check_ratio(path, declared, compressed)
    return LEGACY_HEADER.size + declared + MAX_EXTENSION_BYTES


def _load_legacy(path: Path, payload: bytes | bytearray, container: str, progress: LoadProgress) -> Scene:
    if len(payload) < LEGACY_HEADER.size:
        raise SceneFormatError(path, f"{len(payload)} bytes; the spz header needs 16", field="header")
    magic, version, n, sh_degree, frac_bits, flags, _ = LEGACY_HEADER.unpack_from(payload)
    if magic != MAGIC:
        raise SceneFormatError(path, f"not an spz file (magic {magic!r}, expected {MAGIC!r})", field="magic")
    _check_header(path, version, n, sh_degree, range(1, 4))
    sizes = _sizes(version, n, sh_degree)
    body = len(payload) - LEGACY_HEADER.size
    # Extension records sit between the header and the arrays; their size is what the arrays leave over.
    offset = LEGACY_HEADER.size + (max(0, body - sum(sizes.values())) if flags & EXTENSIONS_FLAG else 0)
    streams = {}
    for name, size in sizes.items():
        if offset + size > len(payload):
            raise SceneFormatError(
                path,
                f"truncated: {container} payload ends inside this array ({len(payload) - offset} of {size} bytes)",
                field=name,
            )
        streams[name] = memoryview(payload)[offset : offset + size]
        offset += size
    return _decode(path, version, n, sh_degree, frac_bits, flags, streams, progress)


def _load_ngsp(path: Path, data: bytes | bytearray, progress: LoadProgress) -> Scene:
    if len(data) < NGSP_HEADER.size:
        raise SceneFormatError(path, f"{len(data)} bytes; the NGSP header needs {NGSP_HEADER.size}", field="header")
    _, version, n, sh_degree, frac_bits, flags, num_streams, toc = NGSP_HEADER.unpack_from(data)
    _check_header(path, version, n, sh_degree, range(4, 5))
    sizes = {k: v for k, v in _sizes(version, n, sh_degree).items() if v}
    _check_ratio(path, sum(sizes.values()), len(data))
    if num_streams != len(sizes):
        raise SceneFormatError(
            path, f"{num_streams} streams; SH degree {sh_degree} needs {len(sizes)}", field="numStreams"
        )
    start = toc + num_streams * TOC_ENTRY.size
    if toc < NGSP_HEADER.size or start > len(data):
        raise SceneFormatError(
            path, f"TOC at {toc} does not fit in the file ({len(data)} bytes)", field="tocByteOffset"
        )
    _check_extensions(path, data, toc)
    dctx = zstandard.ZstdDecompressor()
    streams = {}
    for i, (name, size) in enumerate(sizes.items()):
        compressed, uncompressed = TOC_ENTRY.unpack_from(data, toc + i * TOC_ENTRY.size)
        where = f"stream '{name}'"
        if uncompressed != size:
            raise SceneFormatError(path, f"TOC says {uncompressed} bytes, expected {size}", field=where)
        if start + compressed > len(data):
            raise SceneFormatError(
                path,
                f"truncated: needs {compressed} compressed bytes at {start}, the file has {len(data) - start}",
                field=where,
            )
        progress.check()
        frame = memoryview(data)[start : start + compressed]
        try:
            declared = zstandard.get_frame_parameters(frame).content_size
            if declared not in (size, zstandard.CONTENTSIZE_UNKNOWN):
                raise SceneFormatError(path, f"zstd frame declares {declared} bytes, expected {size}", field=where)
            out = dctx.decompress(frame, max_output_size=size)
        except zstandard.ZstdError as exc:
            raise SceneFormatError(path, f"corrupt zstd stream: {exc}", field=where) from None
        if len(out) != size:
            raise SceneFormatError(path, f"zstd stream gave {len(out)} bytes, expected {size}", field=where)
        streams[name] = out
        start += compressed
    streams.setdefault("sh", b"")
    return _decode(path, version, n, sh_degree, frac_bits, flags, streams, progress)


def _check_extensions(path: Path, data: bytes, end: int) -> None:
    """Walk the (type, length, payload) extension records between the header and the TOC."""
    pos = NGSP_HEADER.size
    while pos < end:
        if pos + 8 > end:
            raise SceneFormatError(path, f"extension record header at {pos} overruns the TOC", field="extensions")
        pos += 8 + struct.unpack_from("<I", data, pos + 4)[0]
        if pos > end:
            raise SceneFormatError(path, "extension record payload overruns the TOC", field="extensions")


def _decode(
    path: Path, version: int, n: int, sh_degree: int, frac_bits: int, flags: int, streams: dict, progress: LoadProgress
) -> Scene:
    """Vectorised decode of the attribute arrays, then RUB -> RDF; chunks of splats, reported."""
    dim = SH_DIM[sh_degree]
    if dim > 15:
        warnings.warn(f"{path}: SH degree 4 is beyond what gbviewer renders; dropping band 4", stacklevel=4)
    pos = np.frombuffer(streams["positions"], "<f2" if version == 1 else np.uint8).reshape(n, 3, -1)
    alphas = np.frombuffer(streams["alphas"], np.uint8)
    colors = np.frombuffer(streams["colors"], np.uint8).reshape(n, 3)
    log_scales = np.frombuffer(streams["scales"], np.uint8).reshape(n, 3)
    rotations = np.frombuffer(streams["rotations"], "<u4" if version >= 3 else np.uint8).reshape(n, -1)
    rest_bytes = np.frombuffer(streams["sh"], np.uint8).reshape(n, dim, 3)[:, :15]

    def decode(rows: slice) -> tuple:
        if version == 1:
            means = pos[rows, :, 0].astype(np.float32)
        else:
            b = pos[rows].astype(np.int32)
            fixed = b[..., 0] | (b[..., 1] << 8) | (b[..., 2] << 16)
            means = np.ldexp(((fixed ^ 0x800000) - 0x800000).astype(np.float32), -frac_bits)
        dc = (colors[rows].astype(np.float32) * np.float32(1 / 255) - np.float32(0.5)) / np.float32(COLOR_SCALE)
        scales = np.exp(log_scales[rows] / np.float32(16) - np.float32(10))
        if version >= 3:
            comp = rotations[rows, 0]
            shifts = np.array([20, 10, 0], dtype=np.uint32)  # the lowest-index component is packed highest
            fields = (comp[:, None] >> shifts) & 0x3FF
            others = (fields & 0x1FF).astype(np.float32) * np.float32(np.sqrt(0.5) / 511)
            others = np.where(fields & 0x200, -others, others)
            xyzw = smallest_three(others, (comp >> 30).astype(np.intp))
        else:
            xyz = rotations[rows] / np.float32(127.5) - np.float32(1)
            w = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", xyz, xyz)))
            xyzw = np.concatenate([xyz, w[:, None]], axis=1)
        quats = np.concatenate([xyzw[:, 3:], xyzw[:, :3] * FLIP_XYZ], axis=1)
        rest = (rest_bytes[rows] - np.float32(128)) / np.float32(128)
        sh = np.concatenate([dc[:, None, :], rest * FLIP_SH[: rest.shape[1], None]], axis=1)
        return means * FLIP_XYZ, scales, quats, alphas[rows] * np.float32(1 / 255), sh

    means, scales, quats, opacities, sh = decode_in_chunks(n, decode, progress)
    meta = {
        "format": "spz",
        "version": version,
        "properties": list(streams),
        "sh_degree_stored": sh_degree,
        "fractional_bits": frac_bits,
        "antialiased": bool(flags & ANTIALIASED_FLAG),
    }
    return Scene.from_arrays(means, scales, quats, opacities, sh, source=str(path), meta=meta)
