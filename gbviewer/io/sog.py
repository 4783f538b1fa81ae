"""PlayCanvas SOG v2: `meta.json` plus lossless WebP images, bundled in a zip (`.sog`) or in a folder.

Pixel i (row-major) of every per-splat image belongs to splat i. means_l/means_u: low/high bytes of
16-bit fractions of the [mins, maxs] range of sign(x) * log(|x| + 1); quats: three components
(byte / 255 * 2 - 1) / sqrt2 in (w, x, y, z) order skipping the largest, whose index + 252 is in
alpha; scales: RGB index a 256-entry codebook of log scales; sh0: RGB index a codebook of DC
coefficients, alpha = sigmoid(opacity) * 255; optional shN: labels (16-bit, R + 256 G) pick a
palette entry in the centroids image (64 entries per row, one pixel per coefficient, RGB index a
codebook). Positions are in the source `.ply` frame.
"""

from __future__ import annotations

import io
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path, PurePosixPath

import numpy as np
from PIL import Image, features

from ..core.errors import InvalidValue, SceneFormatError
from ..core.validate import open_regular, parse_json
from ..model.scene import Scene
from .packing import MAX_SPLATS, smallest_three
from .progress import LoadProgress

ZIP_MAGIC = b"PK"
META_MAX_BYTES = 4 << 20  # meta.json: codebooks of 256 numbers and file names; real ones are ~10 KB
IMAGE_BYTES_PER_PIXEL = 8  # a lossless WebP of RGBA bytes is < 4.1 bytes per pixel; headroom for other encoders
SPARE_PIXELS = 65536  # beyond twice the pixels the count needs (padding rows, power-of-two textures)
SH_COEFFS = {1: 3, 2: 8, 3: 15}


Reader = Callable[[str, int], bytes]  # (member name, byte limit) -> its bytes
Sizer = Callable[[str], int]  # member name -> its stored size (0 when absent)


def load_sog(path: Path, progress: LoadProgress | None = None) -> Scene:
    """Load a bundled `.sog` zip, a folder holding `meta.json`, or a `meta.json` file with its images. `progress`:
    the stored bytes of the images, reported as each is read and decoded."""
    progress = progress or LoadProgress()
    is_zip = False
    if not path.is_dir():
        with open(path, "rb") as fh:
            is_zip = fh.read(2) == ZIP_MAGIC
    if not is_zip:
        folder, meta_name = (path, "meta.json") if path.is_dir() else (path.parent, path.name)
        return _load(
            path,
            lambda name, limit: _read_file(folder, name, limit),
            lambda name: _file_size(folder / name),
            False,
            progress,
            meta_name,
        )
    try:
        with zipfile.ZipFile(path) as zf:
            return _load(
                path,
                lambda name, limit: _read_member(path, zf, name, limit),
                lambda name: _member_size(zf, name),
                True,
                progress,
            )
    except (
        zipfile.BadZipFile,
        zipfile.LargeZipFile,
        OSError,
        EOFError,
        NotImplementedError,
        RuntimeError,
        ValueError,
    ) as exc:  # ValueError: member names that are not valid UTF-8, among others
        raise SceneFormatError(path, f"corrupt .sog zip: {exc}", field="zip") from None


def _too_big(where: Path, name: str, size: int, limit: int) -> SceneFormatError:
    return SceneFormatError(where, f"{size} bytes or more; at most {limit} expected for this splat count", field=name)


def _file_size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0  # missing: reading it says so


def _member_size(zf: zipfile.ZipFile, name: str) -> int:
    try:
        return zf.getinfo(name).compress_size
    except KeyError:
        return 0  # missing: reading it says so


def _read_file(folder: Path, name: str, limit: int) -> bytes:
    try:
        with open_regular(folder / name) as fh:  # a FIFO in its place would block
            data = fh.read(limit + 1)
    except FileNotFoundError:
        raise SceneFormatError(folder, "missing file in the SOG folder", field=name) from None
    except OSError as exc:
        raise SceneFormatError(folder, f"cannot read it ({exc.strerror or exc})", field=name) from None
    if len(data) > limit:
        raise _too_big(folder / name, name, len(data), limit)
    return data


def _read_member(path: Path, zf: zipfile.ZipFile, name: str, limit: int) -> bytes:
    """A zip member read through at most `limit` + 1 inflated bytes, whatever its header claims."""
    try:
        info = zf.getinfo(name)
    except KeyError:
        raise SceneFormatError(path, "missing from the .sog zip", field=name) from None
    if info.file_size > limit:
        raise _too_big(path, name, info.file_size, limit)
    try:
        with zf.open(info) as fh:
            data = fh.read(limit + 1)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, NotImplementedError, RuntimeError) as exc:
        raise SceneFormatError(path, f"cannot read zip member: {exc}", field=name) from None
    if len(data) > limit:
        raise _too_big(path, name, len(data), limit)
    return data


def _load(
    where: Path, read: Reader, size: Sizer, bundled: bool, progress: LoadProgress, meta_name: str = "meta.json"
) -> Scene:
    def hashed(name: str, limit: int) -> bytes:  # each file or member: a part of the load's digest
        data = read(name, limit)
        progress.digest.add(name, 0, data)
        return data

    try:
        meta = parse_json(hashed(meta_name, META_MAX_BYTES), meta_name)
    except InvalidValue as exc:
        raise SceneFormatError(where, str(exc).removeprefix(f"{meta_name}: "), field=meta_name) from None
    try:
        return _decode(where, _Images(where, hashed, size, meta, progress), meta, bundled)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise SceneFormatError(where, f"malformed meta.json: {type(exc).__name__}: {exc}", field="meta.json") from None


def _codebook(where: Path, section: dict, name: str) -> np.ndarray:
    book = np.asarray(section["codebook"], dtype=np.float32)
    if book.shape != (256,):
        raise SceneFormatError(where, f"shape {book.shape}; expected 256 entries", field=f"{name}.codebook")
    return book


def _decode(where: Path, images: _Images, meta: dict, bundled: bool) -> Scene:
    n = images.count

    lo, hi = images.get(meta["means"]["files"][0]), images.get(meta["means"]["files"][1])
    mins = np.asarray(meta["means"]["mins"], dtype=np.float64).reshape(3)
    span = np.asarray(meta["means"]["maxs"], dtype=np.float64).reshape(3) - mins
    span[span == 0] = 1.0
    t = mins + span * ((lo[:, :3] | (hi[:, :3].astype(np.uint16) << 8)) / 65535.0)
    with np.errstate(over="ignore"):  # absurd ranges give inf, and Scene drops those splats
        means = np.sign(t) * np.expm1(np.abs(t))

    q = images.get(meta["quats"]["files"][0])
    if (q[:, 3] < 252).any():
        raise SceneFormatError(where, "quaternion tag (alpha) below 252", field=meta["quats"]["files"][0])
    quats = smallest_three(
        (q[:, :3] / np.float32(127.5) - np.float32(1)) / np.float32(np.sqrt(2)), (q[:, 3] - 252).astype(np.intp)
    )

    scales = np.exp(_codebook(where, meta["scales"], "scales")[images.get(meta["scales"]["files"][0])[:, :3]])
    c = images.get(meta["sh0"]["files"][0])
    sh = _codebook(where, meta["sh0"], "sh0")[c[:, None, :3]]
    opacities = c[:, 3] / np.float32(255)
    if meta.get("shN"):
        sh = np.concatenate([sh, _sh_rest(where, images, meta["shN"], n)], axis=1)

    images.done()
    info = {
        "format": "sog",
        "version": 2,
        "bundled": bundled,
        "antialiased": bool(meta.get("antialias", False)),
        "properties": sorted(k for k in meta if isinstance(meta[k], dict) and "files" in meta[k]),
    }
    return Scene.from_arrays(means, scales, quats, opacities, sh, source=str(where), meta=info)


def _sh_rest(where: Path, images: "_Images", shn: dict, n: int) -> np.ndarray:
    """Higher SH bands from the palette: (N, K-1, 3)."""
    bands, palette = shn["bands"], shn["count"]
    if bands not in SH_COEFFS or not isinstance(palette, int) or not 0 < palette <= 65536:
        raise SceneFormatError(
            where, f"bands {bands!r}, count {palette!r}; expected bands 1-3, count 1..65536", field="shN"
        )
    k = SH_COEFFS[bands]
    centroids_name, labels_name = shn["files"][0], shn["files"][1]
    centroids, (width, _) = images.decode(centroids_name, palette * k)
    if width != 64 * k or len(centroids) < palette * k:
        raise SceneFormatError(
            where,
            f"centroids image is {width} wide with {len(centroids)} pixels; expected "
            f"{64 * k} wide with at least {palette * k}",
            field=centroids_name,
        )
    labels = images.get(labels_name)
    index = labels[:, 0].astype(np.intp) | (labels[:, 1].astype(np.intp) << 8)
    if index.max() >= palette:
        raise SceneFormatError(where, f"label {index.max()} outside the palette of {palette}", field=labels_name)
    entries = _codebook(where, shn, "shN")[centroids[: palette * k, :3]].reshape(palette, k, 3)
    return entries[index]


class _Images:
    """Decodes the per-splat images, checking they share one size that holds every splat and that neither their
    bytes nor their pixels exceed what that many splats can need (checked from the header, before decoding); the
    stored bytes of each image are reported once it is decoded."""

    def __init__(self, where: Path, read: Reader, stored: Sizer, meta: dict, progress: LoadProgress):
        if not isinstance(meta, dict) or meta.get("version") != 2:
            version = meta.get("version") if isinstance(meta, dict) else None
            raise SceneFormatError(where, f"SOG meta version {version!r}; supported: 2", field="version")
        n = meta["count"]
        if not isinstance(n, int) or not 0 < n <= MAX_SPLATS:
            raise SceneFormatError(where, f"count {n!r}; expected 1..{MAX_SPLATS}", field="count")
        self.where, self.read, self.count, self.size = where, read, n, None
        sections = [meta.get(key) for key in ("means", "quats", "scales", "sh0", "shN")]
        lists = [sec["files"] for sec in sections if isinstance(sec, dict) and isinstance(sec.get("files"), list)]
        self.stored = {name: stored(name) for files in lists for name in files if isinstance(name, str)}
        self.total, self.read_bytes, self.progress = sum(self.stored.values()), 0, progress
        progress.report(0, self.total, "bytes")

    def done(self) -> None:
        self.progress.report(self.total, self.total, "bytes")

    def decode(self, name: str, needed: int | None = None) -> tuple[np.ndarray, tuple[int, int]]:
        """RGBA pixels of image `name`, which must hold `needed` pixels (the splat count by default)."""
        if not isinstance(name, str) or PurePosixPath(name).is_absolute() or ".." in PurePosixPath(name).parts:
            raise SceneFormatError(self.where, f"image name {name!r} must be a relative path", field="files")
        most = 2 * (needed or self.count) + SPARE_PIXELS
        data = self.read(name, IMAGE_BYTES_PER_PIXEL * most + 4096)
        if data[:4] == b"RIFF" and not features.check("webp"):
            raise SceneFormatError(self.where, "this Pillow build cannot decode WebP", field=name)
        try:
            with Image.open(io.BytesIO(data)) as im:
                if im.width * im.height > most:
                    raise SceneFormatError(
                        self.where,
                        f"image is {im.width}x{im.height}; {needed or self.count} "
                        f"pixels are needed, at most {most} allowed",
                        field=name,
                    )
                rgba = np.asarray(im.convert("RGBA"))
        except (OSError, ValueError, Image.DecompressionBombError) as exc:
            raise SceneFormatError(self.where, f"cannot decode image: {exc}", field=name) from None
        self.read_bytes += self.stored.pop(name, 0)
        self.progress.report(min(self.read_bytes, self.total), self.total, "bytes")
        return rgba.reshape(-1, 4), (rgba.shape[1], rgba.shape[0])

    def get(self, name: str) -> np.ndarray:
        pixels, size = self.decode(name)
        if self.size is None:
            self.size = size
        if size != self.size or len(pixels) < self.count:
            raise SceneFormatError(
                self.where,
                f"image is {size[0]}x{size[1]}; expected {self.size[0]}x{self.size[1]} holding {self.count} splats",
                field=name,
            )
        return pixels[: self.count]
