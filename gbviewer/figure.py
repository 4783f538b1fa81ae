"""Images for people: 8-bit conversion, nearest upscaling, labels, comparison grids, atomic writes."""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .camera import Camera
from .errors import GBViewerError
from .render import RenderSettings, get_renderer
from .scene import Scene


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Float RGB in [0, 1] (clipped) to uint8."""
    return (np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def upscale_nearest(img: np.ndarray, height: int, width: int) -> np.ndarray:
    """Nearest-neighbour resize (pixel (i, j) of the result samples the source pixel under its centre)."""
    ys = np.minimum(((np.arange(height) + 0.5) * img.shape[0] / height).astype(int), img.shape[0] - 1)
    xs = np.minimum(((np.arange(width) + 0.5) * img.shape[1] / width).astype(int), img.shape[1] - 1)
    return img[ys][:, xs]


def format_rate(rate: float) -> str:
    """x8, x1, x1/8 style label for a sampling rate."""
    f = Fraction(rate).limit_denominator(64)
    return f"x{f.numerator}" if f.denominator == 1 else f"x{f.numerator}/{f.denominator}"


def parse_rate(text: str) -> float:
    """'1/8', '0.125' or '8' -> float > 0."""
    try:
        value = float(Fraction(text.strip()))
    except (ValueError, ZeroDivisionError):
        raise GBViewerError(f"sampling rate {text!r}; expected a number like 8, 0.125 or 1/8") from None
    if not value > 0:
        raise GBViewerError(f"sampling rate {text!r} must be > 0")
    return value


def _font(size: int) -> ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def draw_label(img: Image.Image, text: str, size: int = 14) -> None:
    """Write `text` in the top-left corner on a dark box."""
    draw = ImageDraw.Draw(img)
    font = _font(size)
    box = draw.textbbox((4, 3), text, font=font)
    draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
    draw.text((4, 3), text, fill=(255, 255, 255), font=font)


@dataclass(frozen=True)
class Cell:
    """One rendered cell of a comparison grid."""

    settings: RenderSettings
    rate: float
    rgb: np.ndarray  # at the render resolution
    stats: dict


def render_grid(scene: Scene, camera: Camera, settings: list[RenderSettings], rates: list[float],
                backend: str = "cpu") -> list[list[Cell]]:
    """Render every (rate, settings) pair: rows are rates, columns are settings."""
    renderer = get_renderer(scene, backend)
    rows = []
    for rate in rates:
        cam = camera.at_sampling_rate(rate)
        row = []
        for s in settings:
            frame = renderer.render(cam, s)
            row.append(Cell(s, rate, frame.rgb, frame.stats))
        rows.append(row)
    return rows


def compose_grid(cells: list[list[Cell]], width: int, height: int, gap: int = 4) -> Image.Image:
    """Labelled grid: each cell nearest-upscaled to width x height and captioned with mode, rate and time."""
    n_rows, n_cols = len(cells), len(cells[0])
    out = Image.new("RGB", (n_cols * width + (n_cols - 1) * gap, n_rows * height + (n_rows - 1) * gap), (40, 40, 40))
    for r, row in enumerate(cells):
        for c, cell in enumerate(row):
            tile = Image.fromarray(upscale_nearest(to_uint8(cell.rgb), height, width))
            h, w = cell.rgb.shape[:2]
            draw_label(tile, f"{cell.settings.label}  {format_rate(cell.rate)} ({w}x{h})  "
                             f"{cell.stats.get('total_ms', 0):.0f} ms")
            out.paste(tile, (c * (width + gap), r * (height + gap)))
    return out


def atomic_write(path: str | Path, write, force: bool = False) -> Path:
    """Call write(tmp_path) then rename onto `path`; refuse to overwrite an existing file unless `force`."""
    path = Path(path)
    if path.exists() and not force:
        raise GBViewerError(f"{path}: exists; pass --force to overwrite")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def save_image(path: str | Path, img: Image.Image | np.ndarray, force: bool = False) -> Path:
    """Write a PNG (uint8 RGB) atomically, or for .npy the float array itself."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        arr = np.asarray(img, dtype=np.float32)
        return atomic_write(path, lambda p: np.save(p, arr), force)
    pil = img if isinstance(img, Image.Image) else Image.fromarray(to_uint8(img))
    return atomic_write(path, lambda p: pil.save(p, format="PNG"), force)
