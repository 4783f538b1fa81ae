"""The backdrop of a dataset's photos and the one rule of the background a scene renders on against them
(`choose_background`: the viewer, eval, compare and bench). The backdrop is the median colour of the photos'
borders, where a capture's backdrop shows; for opaque photos (a COLMAP capture) it is the default background: a
render on black against photos of a grey backdrop reads a few dB however good the scene is."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...core.errors import GBViewerError
from .dataset import View
from .photos import read_photo

MAX_PHOTOS = 8  # photos sampled for the estimate (spread over the dataset)
BORDER = 2  # pixels of each photo's border ring that count
BINS = 32  # levels per channel of the colours counted
RGB = tuple[float, float, float]
GIVEN, PHOTOS, DEFAULT = "given", "photos", "default"  # where a background comes from


@dataclass(frozen=True)
class Backdrop:
    """What the photos' borders say: their median colour, whether every photo sampled is opaque, and how many."""

    colour: RGB
    opaque: bool
    photos: int

    def describe(self) -> str:
        """'0.80 0.80 0.80, the median border colour of 8 opaque photos'."""
        kind = "opaque" if self.opaque else "RGBA"
        return f"{format_rgb(self.colour)}, the median border colour of {self.photos} {kind} photos"


def format_rgb(rgb: Sequence[float]) -> str:
    return " ".join(f"{c:.2f}" for c in rgb)


def border(pixels: np.ndarray, width: int = BORDER) -> np.ndarray:
    """The (N, C) pixels of an image's border ring `width` pixels wide."""
    h, w = pixels.shape[:2]
    mask = np.zeros((h, w), bool)
    mask[:width], mask[-width:], mask[:, :width], mask[:, -width:] = True, True, True, True
    return pixels[mask]


def estimate_backdrop(views: Sequence[View], limit: int = MAX_PHOTOS) -> Backdrop | None:
    """The backdrop in the borders of up to `limit` of the views' photos (evenly spread; `backdrop_colour`); None
    when none can be read.
    RGBA photos count only their opaque border pixels (alpha > 0.5); such a dataset is not `opaque`."""
    if not views:
        return None
    picks = sorted({round(i) for i in np.linspace(0, len(views) - 1, min(limit, len(views)))})
    rings, opaque, read = [], True, 0
    for i in picks:
        try:
            photo = read_photo(views[i].image)
        except GBViewerError:
            continue
        read += 1
        ring = border(photo)
        if photo.shape[2] == 4:
            opaque = opaque and bool((photo[..., 3] >= 1.0).all())
            ring = ring[ring[:, 3] > 0.5]
        rings.append(ring[:, :3])
    if not read:
        return None
    pixels = np.concatenate(rings) if rings else np.zeros((0, 3), np.float32)
    return Backdrop(backdrop_colour(pixels), opaque, read)


def backdrop_colour(pixels: np.ndarray) -> RGB:
    """The median of the (N, 3) border pixels in their commonest colour (RGB in BINS levels each): where the
    scene's faint edges reach most of the border, the plain median would be shifted by them."""
    if not len(pixels):
        return (0.0, 0.0, 0.0)
    q = np.minimum((pixels * BINS).astype(np.int64), BINS - 1)
    code = (q[:, 0] * BINS + q[:, 1]) * BINS + q[:, 2]
    values, counts = np.unique(code, return_counts=True)
    return tuple(float(c) for c in np.median(pixels[code == values[np.argmax(counts)]], axis=0))


@dataclass(frozen=True)
class Background:
    """The colour a scene renders on against its photos and where it comes from (GIVEN, PHOTOS or DEFAULT)."""

    colour: RGB
    source: str
    backdrop: Backdrop | None = None

    def describe(self) -> str:
        """'0.80 0.80 0.80, the median border colour of 8 opaque photos', '1.00 1.00 1.00 (given)', ..."""
        if self.source == PHOTOS and self.backdrop is not None:
            return self.backdrop.describe()
        if self.source == GIVEN:
            return f"{format_rgb(self.colour)} (given)"
        why = "no photos" if self.backdrop is None else "the photos have alpha: they are composited on it"
        return f"{format_rgb(self.colour)} (default: {why})"

    def to_json(self) -> dict:
        return {"rgb": list(self.colour), "source": self.source, "describe": self.describe()}


def choose_background(given: Sequence[float] | None, backdrop: Backdrop | None) -> Background:
    """The background of every surface that renders a scene against its photos (viewer, eval, compare, bench):
    the colour the user gave; else the photos' backdrop when every photo sampled is opaque; else black (RGBA photos,
    a Blender set, are composited on it instead)."""
    if given is not None:
        return Background(tuple(float(c) for c in given), GIVEN, backdrop)
    if backdrop is not None and backdrop.opaque:
        return Background(backdrop.colour, PHOTOS, backdrop)
    return Background((0.0, 0.0, 0.0), DEFAULT, backdrop)
