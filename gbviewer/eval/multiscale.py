"""Multi-scale ground truth: a dataset's photo box-downsampled by k with colour weighted by alpha and composited
on the background (the paper's appendix B.2), cached on disk outside the dataset."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.errors import GBViewerError
from ..core.files import atomic_write
from ..core.validate import open_regular, read_npy
from ..io.datasets import View, read_photo
from ..model.camera import Camera, format_rate
from ..outputs.metrics import composite, premultiplied_box_downsample, zoom_factor

CACHE_VERSION = 2  # part of every key: a change of what is stored (or of the key) invalidates the old entries
DIGEST_CHUNK = 1 << 20  # bytes of a photo hashed at a time


def default_cache() -> Path:
    """The user's cache folder for box-downsampled photos (XDG_CACHE_HOME/gbviewer/ground_truth on Linux)."""
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("gbviewer")) / "ground_truth"


def rate_factor(rate: float) -> int:
    """k of a rate 1/k: the photos box-downsampled by k are its ground truth. Rates above 1 would need photos finer
    than the dataset's (the paper's zoom-in is a scene trained on downsampled photos evaluated against full-size
    ones: point the dataset at the full-size photos instead)."""
    k = zoom_factor(rate) if rate <= 1 else None
    if k is None:
        why = (
            "is finer than the photos (x1); evaluate a scene trained on downsampled photos against the full-size "
            "ones for zoom-in"
            if rate > 1
            else "is not 1/k for an integer k"
        )
        raise GBViewerError(f"rate {format_rate(rate)} {why}")
    return k


def camera_for_rate(camera: Camera, rate: float) -> Camera:
    """The camera whose pixels are those of the ground truth at `rate`: the photo's camera with the ragged right and
    bottom edges that box_downsample crops cut off (intrinsics unchanged), then k times coarser."""
    k = rate_factor(rate)
    if k > min(camera.width, camera.height):
        raise GBViewerError(
            f"rate {format_rate(rate)}: the photo {camera.name!r} ({camera.width}x{camera.height}) "
            f"is smaller than {k} pixels"
        )
    cropped = replace(camera, width=camera.width // k * k, height=camera.height // k * k)
    return cropped.at_sampling_rate(1 / k) if k > 1 else cropped


def photo_digest(photo: Path) -> str:
    """The SHA-256 of the photo's bytes: what its cached levels are keyed by (its path, size and modification time
    do not tell a same-size edit whose time was restored, as cp -p, rsync -a and tar do)."""
    h = hashlib.sha256()
    try:
        with open_regular(photo) as fh:
            while chunk := fh.read(DIGEST_CHUNK):
                h.update(chunk)
    except OSError as exc:
        raise GBViewerError(f"{photo}: cannot read the photo ({exc.strerror or exc})") from None
    return h.hexdigest()


def _entry(cache: Path, digest: str, k: int) -> Path:
    """The cache file of the photo of `digest` (`photo_digest`) at factor k."""
    key = f"{CACHE_VERSION}\0{digest}\0{k}"
    return cache / f"{hashlib.sha256(key.encode()).hexdigest()[:40]}.npy"


def _cached(entry: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """The stored level when it is what it must be (a regular file of float32 RGB or RGBA of the expected size,
    every value in [0, 1], checked from its header before its data is read); else None: an entry is untrusted."""
    try:
        with open_regular(entry) as fh:
            level = read_npy(fh, str(entry), [(*shape, 3), (*shape, 4)], np.dtype(np.float32))
    except (OSError, ValueError, EOFError):
        return None
    with np.errstate(invalid="ignore"):
        return level if level.size and 0 <= level.min() and level.max() <= 1 else None  # NaN fails both


def ground_truths(
    view: View, rates: Sequence[float], background: tuple[float, float, float], cache: Path | None = None
) -> list[np.ndarray]:
    """float32 (H/k, W/k, 3) ground truth of `view` at each rate 1/k (x1: the photo), on `background` where the
    photo has alpha. The photo is decoded at most once; levels k > 1 are read from and written to `cache` (a
    folder; None: no cache). Sizes come from `camera_for_rate`."""
    ks = [rate_factor(r) for r in rates]
    for r in rates:
        camera_for_rate(view.camera, r)  # every k fits the photo
    levels: dict[int, np.ndarray] = {}
    digest = photo_digest(view.image) if cache is not None and any(k > 1 for k in ks) else ""
    for k in {k for k in ks if k > 1 and cache is not None}:
        hit = _cached(_entry(cache, digest, k), (view.camera.height // k, view.camera.width // k))
        if hit is not None:
            levels[k] = hit
    missing = [k for k in dict.fromkeys(ks) if k not in levels]
    if missing:
        photo = read_photo(view.image)
        if photo.shape[:2] != (view.camera.height, view.camera.width):
            raise GBViewerError(
                f"{view.image}: photo is now {photo.shape[1]}x{photo.shape[0]}; its camera is "
                f"{view.camera.width}x{view.camera.height}"
            )
        for k in missing:
            levels[k] = premultiplied_box_downsample(photo, k)
            if k > 1 and cache is not None:
                atomic_write(_entry(cache, digest, k), lambda p, a=levels[k]: np.save(p, a), force=True)
    return [composite(levels[k], background) for k in ks]


def ground_truth(
    view: View, rate: float, background: tuple[float, float, float] = (0.0, 0.0, 0.0), cache: Path | None = None
) -> np.ndarray:
    """float32 (H, W, 3) ground truth of `view` at `rate` (see `ground_truths`); render `camera_for_rate(
    view.camera, rate)` to compare with it."""
    return ground_truths(view, [rate], background, cache)[0]
