"""A COLMAP text model's cameras.txt and images.txt checked line by line before pycolmap reads them, so that a
malformed line is named (file, line, what was expected) rather than shown as pycolmap's internal check message."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator

from ...core.errors import DatasetError

PARAMS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8, "FULL_OPENCV": 12}
OTHER_MODELS = {
    "SIMPLE_RADIAL_FISHEYE",
    "RADIAL_FISHEYE",
    "OPENCV_FISHEYE",
    "FOV",
    "THIN_PRISM_FISHEYE",
    "RAD_TAN_THIN_PRISM_FISHEYE",
    "SIMPLE_DIVISION",
    "DIVISION",
    "SIMPLE_FISHEYE",
    "FISHEYE",
    "EUCM",
    "EQUIRECTANGULAR",
}  # COLMAP's other models: read, then refused by name (`colmap.pinhole`)
IMAGE_FIELDS = 9  # IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID, then NAME


def _numbers(tokens: list[str], where: str, ints: tuple[int, ...] = ()) -> None:
    """Each token a finite number (those at `ints` integers); else a one-line error."""
    for i, tok in enumerate(tokens):
        try:
            value = int(tok) if i in ints else float(tok)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value):
            kind = "an integer" if i in ints else "finite numbers"
            raise DatasetError(f"{where}: expected {kind}, got {tok!r:.40} (item {i + 1})")


def _lines(path: Path) -> Iterator[str]:
    """The file's lines, streamed (an images.txt with its points can be large)."""
    try:
        with open(path, encoding="utf-8", errors="replace", newline="\n") as fh:
            yield from fh
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read it ({exc.strerror or exc})") from None


def check_cameras(path: Path) -> None:
    """Every camera line 'CAMERA_ID MODEL WIDTH HEIGHT PARAMS...': integers, a COLMAP model with its number of
    finite parameters."""
    for n, line in enumerate(_lines(path), 1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        where = f"{path} line {n}"
        if len(tokens) < 4:
            raise DatasetError(f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., got {len(tokens)} items")
        model = tokens[1]
        if model not in PARAMS and model not in OTHER_MODELS:
            raise DatasetError(f"{where}: unknown camera model {model!r:.40}; supported: {', '.join(PARAMS)}")
        _numbers([tokens[0], *tokens[2:4]], where, ints=(0, 1, 2))
        _numbers(tokens[4:], f"{where}: {model} parameters")
        if model in PARAMS and len(tokens) - 4 != PARAMS[model]:
            raise DatasetError(f"{where}: {model} has {PARAMS[model]} parameters, got {len(tokens) - 4}")


def check_images(path: Path) -> None:
    """Every image line 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME' (finite numbers) and the points line after it
    (X Y POINT3D_ID triples, counted but not parsed: they can be millions; COLMAP reads that line whatever it
    holds, blank included)."""
    points_next = False
    for n, line in enumerate(_lines(path), 1):
        tokens = line.split()
        where = f"{path} line {n}"
        if points_next:
            points_next = False
            if len(tokens) % 3:
                raise DatasetError(
                    f"{where}: expected X Y POINT3D_ID triples (the image line's points), got {len(tokens)} items"
                )
        elif tokens and not tokens[0].startswith("#"):
            if len(tokens) < IMAGE_FIELDS + 1:
                raise DatasetError(
                    f"{where}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {len(tokens)} items"
                )
            _numbers(tokens[:IMAGE_FIELDS], where, ints=(0, 8))
            points_next = True


def check_text_model(folder: Path) -> None:
    """cameras.txt and images.txt of `folder` (a text model) checked before pycolmap reads them."""
    check_cameras(folder / "cameras.txt")
    check_images(folder / "images.txt")
