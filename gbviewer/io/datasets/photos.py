"""The photos of a dataset: their sizes from the file headers, checked against the cameras, and their pixels.

A photo is PNG or JPEG, told by its first bytes (not its name); anything else Pillow could open is refused. Before
anything is decoded, its header must describe no more pixels than its bytes can encode, a decoded size (width x
height x channels x bytes per channel, and the float32 array made of it) within MAX_DECODED_BYTES and, for JPEG, at
most MAX_JPEG_SCANS scans (a progressive JPEG of thousands of scans decodes for minutes): the decode's time and
memory are bounded by what it produces."""

from __future__ import annotations

import errno
import os
import struct
import warnings
from pathlib import Path

import numpy as np
from PIL import Image

from ...core.errors import DatasetError
from ...model.camera import MAX_IMAGE_SIZE, Camera

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".JPG", ".JPEG", ".PNG")  # tried for a name given without one
PIXELS_PER_BYTE = 4096  # beyond what PNG (deflate: < 1032:1) or JPEG can compress: a header claiming more is false
MAGIC = {"PNG": b"\x89PNG\r\n\x1a\n", "JPEG": b"\xff\xd8\xff"}  # the photo formats a dataset may hold
MAX_DECODED_BYTES = 4 << 30  # decoded pixels plus their float32 copy, per photo
MAX_JPEG_SCANS = 100  # libjpeg-turbo's advice against scan bombs (djpeg -maxscan); real progressive JPEGs have ~10
# what Pillow raises for a malformed file: OSError, SyntaxError (a broken PNG chunk), EOFError, struct.error, ...
DECODE_ERRORS = (OSError, ValueError, SyntaxError, EOFError, struct.error, IndexError, Image.DecompressionBombError)
# the photo modes read, each with its largest value (16-bit grey PNGs open as I;16; a palette is expanded first)
PHOTO_RANGES = {"1": 1, "L": 255, "LA": 255, "RGB": 255, "RGBA": 255, "I;16": 65535, "I;16B": 65535, "I;16L": 65535}
SOS = b"\xff\xda"  # JPEG start of scan: entropy-coded data stuffs 0xff with 0x00, so only markers hold this pair


def photo_format(path: Path) -> str:
    """PNG or JPEG, from the file's first bytes; any other content is a one-line `DatasetError`."""
    with open(path, "rb") as fh:
        head = fh.read(8)
    for name, magic in MAGIC.items():
        if head.startswith(magic):
            return name
    raise DatasetError(
        f"{path}: not a PNG or JPEG photo (it starts with {head.hex(' ') or 'nothing'}); a dataset's "
        "photos must be PNG or JPEG"
    )


def _open(path: Path) -> Image.Image:
    """Image.open of a PNG or JPEG (by content) without Pillow's decompression-bomb warning: `photo_size` bounds
    the pixels itself (Pillow's error above twice its warning limit stays)."""
    kind = photo_format(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        return Image.open(path, formats=[kind])


def _decoded_bytes(im: Image.Image) -> int:
    """Bytes of the decoded pixels (channels x bytes per channel, 16-bit PNGs included) and of their float32 RGBA
    copy."""
    w, h = im.size
    channel = 2 if im.mode.startswith("I;16") else 4 if im.mode in ("I", "F") else 1
    return w * h * (len(im.getbands()) * channel + 4 * 4)


def _scans(path: Path) -> int:
    with open(path, "rb") as fh:
        return fh.read().count(SOS)


def photo_size(path: Path) -> tuple[int, int]:
    """(width, height) from the image header, each 1..MAX_IMAGE_SIZE, together no more pixels than the file's
    bytes can encode and no more decoded bytes than MAX_DECODED_BYTES (a JPEG: at most MAX_JPEG_SCANS scans);
    nothing is decoded."""
    try:
        with _open(path) as im:
            w, h = im.size
            decoded, kind = _decoded_bytes(im), im.format
        size = path.stat().st_size
        scans = _scans(path) if kind in ("JPEG", "MPO") else 0  # MPO: a phone's JPEG with more pictures appended
    except FileNotFoundError:
        raise DatasetError(f"{path}: photo missing") from None
    except DECODE_ERRORS as exc:
        raise DatasetError(f"{path}: cannot read the photo ({exc})") from None
    if not (1 <= w <= MAX_IMAGE_SIZE and 1 <= h <= MAX_IMAGE_SIZE):
        raise DatasetError(f"{path}: photo is {w}x{h}; expected sides of 1..{MAX_IMAGE_SIZE} pixels")
    if w * h > PIXELS_PER_BYTE * size:
        raise DatasetError(f"{path}: header claims {w}x{h} pixels in {size} bytes; not a real photo")
    if decoded > MAX_DECODED_BYTES:
        raise DatasetError(
            f"{path}: a {w}x{h} photo decodes to {decoded / (1 << 30):.3g} GiB; at most "
            f"{MAX_DECODED_BYTES >> 30} GiB per photo"
        )
    if scans > MAX_JPEG_SCANS:
        raise DatasetError(
            f"{path}: JPEG of {scans} scans; at most {MAX_JPEG_SCANS} (a progressive JPEG of many "
            "scans takes minutes to decode)"
        )
    return w, h


def read_photo(path: Path) -> np.ndarray:
    """The photo as float32 in [0, 1], each value divided by its mode's largest (255, 65535 for 16-bit grey, 1 for
    1-bit): (H, W, 4) straight RGBA when it has an alpha channel (or a transparent palette entry or colour),
    (H, W, 3) RGB otherwise; grey repeated in R, G and B. Pillow holds 16-bit colour PNGs at 8 bits (their high
    bytes). Other modes (CMYK) are a one-line `DatasetError`. Size, format and scans are checked from the file
    before decoding."""
    photo_size(path)
    try:
        with _open(path) as im:
            if im.mode not in PHOTO_RANGES and im.mode not in ("P", "PA"):
                raise DatasetError(
                    f"{path}: a {im.mode} photo; expected greyscale, RGB or RGBA (8 or 16 bits, a "
                    "palette or 1 bit)"
                    + (": convert it to RGB (its colours depend on a print profile)" if im.mode == "CMYK" else "")
                )
            return _pixels(im)
    except DECODE_ERRORS as exc:
        raise DatasetError(f"{path}: cannot decode the photo ({exc})") from None


def _pixels(im: Image.Image) -> np.ndarray:
    """`read_photo`'s array of an open image in one of PHOTO_RANGES' modes (a palette's expanded to RGB(A))."""
    if im.mode in ("P", "PA"):
        im = im.convert("RGBA" if im.mode == "PA" or "transparency" in im.info else "RGB")
    raw = np.asarray(im)
    raw = raw[..., None] if raw.ndim == 2 else raw
    scale = np.float32(PHOTO_RANGES[im.mode])
    alpha_band = im.mode in ("LA", "RGBA")
    colour = raw[..., :-1] if alpha_band else raw
    rgb = np.repeat(colour, 3, axis=-1) if colour.shape[-1] == 1 else colour
    out = rgb.astype(np.float32) / scale
    key = None if alpha_band else im.info.get("transparency")  # tRNS: the one colour that is transparent
    if alpha_band:
        alpha = raw[..., -1:].astype(np.float32) / scale
    elif key is not None and not isinstance(key, bytes):
        alpha = np.all(colour != np.reshape(key, (1, 1, -1)), axis=-1, keepdims=True).astype(np.float32)
    else:
        return out
    return np.concatenate([out, alpha], axis=-1)


def find_photo(folder: Path, name: str) -> Path:
    """`folder/name`, or with one of PHOTO_SUFFIXES added when `name` has none that exists (3DGS cameras.json and
    Blender transforms name photos without their extension)."""
    path = photo_path(folder, name)
    if is_photo_file(path):
        return path
    for suffix in PHOTO_SUFFIXES:
        candidate = folder / f"{name}{suffix}"
        if is_photo_file(candidate):
            return candidate
    return path


def photo_path(folder: Path, name: str) -> Path:
    """`folder/name` for a relative `name` that stays in `folder` (subfolders allowed); an absolute name or one with
    `..` (a dataset pointing at files elsewhere) is a `DatasetError`."""
    rel = Path(name)
    if rel.is_absolute() or ".." in rel.parts or "\0" in name or not name.strip():
        raise DatasetError(f"{folder}: photo name {name!r:.200}; expected a path inside this folder")
    return folder / rel


def is_photo_file(path: Path) -> bool:
    """Whether `path` is a file; a name the file system cannot hold (over NAME_MAX bytes) is a `DatasetError`."""
    try:
        return path.is_file()
    except OSError as exc:
        if exc.errno != errno.ENAMETOOLONG:
            raise DatasetError(f"{path}: cannot look for this photo ({exc.strerror or exc})") from None
        longest = max(len(p.encode(errors="surrogateescape")) for p in path.parts)
        raise DatasetError(
            f"{str(path)[:100]}...: photo name of {longest} bytes; a file name holds at most "
            f"{os.pathconf(path.anchor or '.', 'PC_NAME_MAX')} bytes"
        ) from None


def missing_photos(paths: list[Path], where: str) -> None:
    """One line naming how many of `paths` do not exist and the first of them."""
    missing = [p for p in paths if not is_photo_file(p)]
    if missing:
        raise DatasetError(
            f"{where}: {len(missing)} of the {len(paths)} photos it names are missing (first: {missing[0]})"
        )


def fit_to_photo(camera: Camera, path: Path, larger: bool = False) -> Camera:
    """The camera at the photo's size, told by its header before anything is decoded: the camera's own size or an
    integer downscale of it (images_2, images_4, ...: each side divided by k, rounded either way), the intrinsics
    rescaled; with `larger` (a cameras.json, which may hold a training size below its photos') also an integer
    upscale. Any other size (a 12000x12000 photo of a 64x64 camera) is a one-line DatasetError."""
    w, h = photo_size(path)
    if (w, h) == (camera.width, camera.height):
        return camera
    if _divided((camera.width, camera.height), (w, h)) or (larger and _divided((w, h), (camera.width, camera.height))):
        return camera.with_size(w, h)
    raise DatasetError(
        f"{path}: photo is {w}x{h} but its camera {camera.name!r} is {camera.width}x{camera.height}; "
        f"expected that size or an integer {'down- or upscale' if larger else 'downscale'} of it "
        "(images_2, images_4, ...)"
    )


def _divided(big: tuple[int, int], small: tuple[int, int]) -> bool:
    """Whether `small` is `big` divided by one integer, each side rounded down or up."""
    k = round(big[0] / small[0])
    return k >= 1 and all(s in (b // k, -(-b // k)) for b, s in zip(big, small))
