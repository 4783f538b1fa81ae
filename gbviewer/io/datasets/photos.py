"""The photos of a dataset: their sizes from the file headers, checked against the cameras, and their pixels."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from PIL import Image

from ...camera import MAX_IMAGE_SIZE, Camera
from ...errors import DatasetError

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".JPG", ".JPEG", ".PNG")  # tried for a name given without one
PIXELS_PER_BYTE = 4096  # beyond what PNG (deflate: < 1032:1) or JPEG can compress: a header claiming more is false


def _open(path: Path) -> Image.Image:
    """Image.open without Pillow's decompression-bomb warning: `photo_size` bounds the pixels itself (Pillow's
    error above twice its warning limit stays)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        return Image.open(path)


def photo_size(path: Path) -> tuple[int, int]:
    """(width, height) from the image header, each 1..MAX_IMAGE_SIZE and together no more pixels than the file's
    bytes can encode; nothing is decoded."""
    try:
        with _open(path) as im:
            w, h = im.size
        size = path.stat().st_size
    except FileNotFoundError:
        raise DatasetError(f"{path}: photo missing") from None
    except (OSError, ValueError, Image.DecompressionBombError) as exc:
        raise DatasetError(f"{path}: cannot read the photo ({exc})") from None
    if not (1 <= w <= MAX_IMAGE_SIZE and 1 <= h <= MAX_IMAGE_SIZE):
        raise DatasetError(f"{path}: photo is {w}x{h}; expected sides of 1..{MAX_IMAGE_SIZE} pixels")
    if w * h > PIXELS_PER_BYTE * size:
        raise DatasetError(f"{path}: header claims {w}x{h} pixels in {size} bytes; not a real photo")
    return w, h


def read_photo(path: Path) -> np.ndarray:
    """The photo as float32 in [0, 1]: (H, W, 4) straight RGBA when it has an alpha channel (or a transparent
    palette entry), (H, W, 3) RGB otherwise. Sides are checked from the header before decoding."""
    photo_size(path)
    try:
        with _open(path) as im:
            alpha = "A" in im.getbands() or "transparency" in im.info
            pixels = np.asarray(im.convert("RGBA" if alpha else "RGB"))
    except (OSError, ValueError, Image.DecompressionBombError) as exc:
        raise DatasetError(f"{path}: cannot decode the photo ({exc})") from None
    return pixels.astype(np.float32) / np.float32(255)


def find_photo(folder: Path, name: str) -> Path:
    """`folder/name`, or with one of PHOTO_SUFFIXES added when `name` has none that exists (3DGS cameras.json and
    Blender transforms name photos without their extension)."""
    path = folder / name
    if path.is_file():
        return path
    for suffix in PHOTO_SUFFIXES:
        candidate = folder / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    return path


def missing_photos(paths: list[Path], where: str) -> None:
    """One line naming how many of `paths` do not exist and the first of them."""
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise DatasetError(f"{where}: {len(missing)} of the {len(paths)} photos it names are missing "
                           f"(first: {missing[0]})")


def fit_to_photo(camera: Camera, path: Path) -> Camera:
    """The camera at the photo's size: intrinsics rescaled when the photo was resized (images_4, a cameras.json of
    3DGS's training resolution), the aspect kept to within a pixel of rounding on each side."""
    w, h = photo_size(path)
    if (w, h) == (camera.width, camera.height):
        return camera
    if abs(w * camera.height - h * camera.width) > camera.width + camera.height:
        raise DatasetError(f"{path}: photo is {w}x{h} but its camera {camera.name!r} is {camera.width}x"
                           f"{camera.height}: not the same aspect ratio")
    return camera.with_size(w, h)
