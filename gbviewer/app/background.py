"""The background the panes render on: a colour the user picks (the panel, `gbviewer view --background`, saved in the
settings) or, with a dataset open, one estimated from its photos: the median colour of their borders, where a
capture's backdrop shows. For opaque photos (a COLMAP capture) that estimate is the default: a render on black
against photos of a grey backdrop reads a few dB however good the scene is. No imgui here."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import GBViewerError
from ..io.datasets import View, read_photo

MAX_PHOTOS = 8  # photos sampled for the estimate (spread over the dataset)
BORDER = 2  # pixels of each photo's border ring that count
BINS = 32  # levels per channel of the colours counted
FIXED, PHOTOS = "fixed", "photos"  # the background's source
RGB = tuple[float, float, float]


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
