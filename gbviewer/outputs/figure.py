"""Images for people: 8-bit conversion, nearest upscaling, labels, labelled grids of renders, and the modes x
rates comparison figure with PSNR under each cell and, on request, rows of differences with their colour bar
(`compare_figure`); PNG written atomically (`save_image`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..core.errors import GBViewerError
from ..core.files import atomic_write, refuse_overwrite
from ..model.camera import Camera, format_rate
from ..model.scene import Scene
from ..render import Frame, FrameStats, Mode, Renderer, RenderSettings, get_renderer
from .differences import (
    MIN_SCALE,
    colour_bar,
    colour_difference,
    format_scale,
    reference_image,
    robust_scale,
    signed_difference,
)
from .metrics import psnr, reference_psnr

GAP = 4  # pixels between cells
DIFFS = {
    "first": "each mode minus the first mode at the same rate",
    "ref": "each mode minus the dense reference (scalar 8x8) at the same rate",
}


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Float RGB in [0, 1] (clipped) to uint8."""
    return (np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def upscale_nearest(img: np.ndarray, height: int, width: int) -> np.ndarray:
    """Nearest-neighbour resize (pixel (i, j) of the result samples the source pixel under its centre)."""
    ys = np.minimum(((np.arange(height) + 0.5) * img.shape[0] / height).astype(int), img.shape[0] - 1)
    xs = np.minimum(((np.arange(width) + 0.5) * img.shape[1] / width).astype(int), img.shape[1] - 1)
    return img[ys][:, xs]


def _font(size: int) -> ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def drawable(text: str) -> str:
    """`text` in the glyphs of Pillow's default font, which has no Greek: the LOD label's tau spelled out."""
    return text.replace("\u03c4", "tau")


def draw_label(img: Image.Image, text: str, size: int = 14) -> None:
    """Write `text` in the top-left corner on a dark box."""
    text = drawable(text)
    draw = ImageDraw.Draw(img)
    font = _font(size)
    box = draw.textbbox((4, 3), text, font=font)
    draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
    draw.text((4, 3), text, fill=(255, 255, 255), font=font)


@dataclass(frozen=True, eq=False)
class Cell:
    """One rendered cell of a comparison grid."""

    settings: RenderSettings
    rate: float
    rgb: np.ndarray  # at the render resolution
    stats: FrameStats

    @classmethod
    def of(cls, settings: RenderSettings, rate: float, frame: Frame) -> "Cell":
        return cls(settings, rate, frame.rgb, frame.stats)

    @property
    def mode_label(self) -> str:
        """The mode as the renderer reports it, else the settings' label."""
        return self.stats.mode or self.settings.label

    @property
    def total_ms(self) -> float:
        """The render's wall time."""
        return self.stats.total_ms


def render_grid(
    scene: Scene, camera: Camera, settings: list[RenderSettings], rates: list[float], backend: str = "cpu"
) -> list[list[Cell]]:
    """Render every (rate, settings) pair: rows are rates, columns are settings."""
    renderer = get_renderer(scene, backend)
    cams = [camera.at_sampling_rate(rate) for rate in rates]
    return [[Cell.of(s, rate, renderer.render(cam, s)) for s in settings] for rate, cam in zip(rates, cams)]


def caption_font_size(height: int) -> int:
    """Caption text size for cells `height` pixels tall (11..22 px)."""
    return max(11, min(22, round(height / 22)))


@dataclass(frozen=True)
class GridLayout:
    """Where `compose_grid` puts things: rows x cols cells of width x height, `gap` apart, each with a caption strip
    `caption_height` tall directly below it (0: labels drawn over the cell), the canvas padded by one pixel on the
    right / bottom where `even` asks for even sizes (H.264 with 4:2:0 chroma needs them)."""

    rows: int
    cols: int
    width: int
    height: int
    gap: int = GAP
    caption_height: int = 0
    even: bool = False

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the whole canvas."""
        w = self.cols * self.width + (self.cols - 1) * self.gap
        h = self.rows * (self.height + self.caption_height) + (self.rows - 1) * self.gap
        return (w + w % 2, h + h % 2) if self.even else (w, h)

    def origin(self, row: int, col: int) -> tuple[int, int]:
        """(x, y) of the top-left pixel of a cell's image; its caption strip starts at y + height."""
        return col * (self.width + self.gap), row * (self.height + self.caption_height + self.gap)

    @staticmethod
    def caption_height_for(lines: int, font_size: int) -> int:
        return 0 if lines == 0 else lines * (font_size + 4) + 6


def draw_inset(
    tile: Image.Image,
    box: tuple[float, float, float, float],
    frac: float = 0.4,
    colour: tuple[int, int, int] = (255, 200, 0),
) -> None:
    """Magnify the region box = (x, y, w, h) (pixels of `tile`) with nearest filtering into the bottom-right corner
    of `tile` (its longer side `frac` of the tile's shorter side), framed, and outline the region itself."""
    x0, y0 = max(0, int(np.floor(box[0]))), max(0, int(np.floor(box[1])))
    x1 = min(tile.width, max(x0 + 1, int(np.ceil(box[0] + box[2]))))
    y1 = min(tile.height, max(y0 + 1, int(np.ceil(box[1] + box[3]))))
    if x0 >= tile.width or y0 >= tile.height or x1 <= x0 or y1 <= y0:
        return
    crop = tile.crop((x0, y0, x1, y1))
    side = max(4, round(frac * min(tile.width, tile.height)))
    scale = side / max(x1 - x0, y1 - y0)
    iw, ih = max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale))
    px, py = tile.width - iw - 3, tile.height - ih - 3
    draw = ImageDraw.Draw(tile)
    draw.rectangle((x0 - 1, y0 - 1, x1, y1), outline=colour)
    tile.paste(crop.resize((iw, ih), Image.Resampling.NEAREST), (px, py))
    draw.rectangle((px - 1, py - 1, px + iw, py + ih), outline=colour)


def _default_lines(cell: Cell) -> list[str]:
    h, w = cell.rgb.shape[:2]
    return [f"{cell.mode_label}  {format_rate(cell.rate)} ({w}x{h})", f"{cell.total_ms:.0f} ms"]


def compose_grid(
    cells: list[list[Cell]],
    width: int,
    height: int,
    gap: int = GAP,
    captions: str = "overlay",
    lines=None,
    inset: tuple[float, float, float, float] | None = None,
    even: bool = False,
    font_size: int | None = None,
) -> Image.Image:
    """Labelled grid: each cell nearest-upscaled to width x height.

    captions="overlay": mode, rate, size and time written over the cell's top-left corner (the demo's look).
    captions="below": the text lines(cell) -> list[str] (default: mode, rate and size; time) in a strip below each
    cell, so every cell's pixels are exactly its nearest-upscaled render (see `GridLayout` for where they are).
    inset: a region (x, y, w, h) in cell pixels (x1 pixels for the grid's full size) magnified into each cell's
    bottom-right corner (`draw_inset`). even: pad the canvas to even sizes.
    """
    if captions not in ("overlay", "below"):
        raise GBViewerError(f"captions {captions!r}; expected 'overlay' or 'below'")
    lines = lines or _default_lines
    fs = font_size or caption_font_size(height)
    texts = [[[drawable(t) for t in lines(cell)] for cell in row] for row in cells] if captions == "below" else None
    n_lines = max((len(t) for row in texts for t in row), default=0) if texts else 0
    layout = GridLayout(len(cells), len(cells[0]), width, height, gap, GridLayout.caption_height_for(n_lines, fs), even)
    out = Image.new("RGB", layout.size, (40, 40, 40))
    font = _font(fs)
    if texts is not None:  # smaller text where a caption would not fit the cell (the strip keeps its height)
        longest = max((t for row in texts for cell_lines in row for t in cell_lines), key=len, default="")
        size = fs
        while size > 8 and ImageDraw.Draw(out).textlength(longest, font=font) > width - 8:
            size -= 1
            font = _font(size)
    for r, row in enumerate(cells):
        for c, cell in enumerate(row):
            rgb = to_uint8(cell.rgb)
            if rgb.shape[:2] != (height, width):
                rgb = upscale_nearest(rgb, height, width)
            tile = Image.fromarray(rgb)
            if inset is not None:
                draw_inset(tile, inset)
            x, y = layout.origin(r, c)
            if texts is None:
                h, w = cell.rgb.shape[:2]
                draw_label(tile, f"{cell.settings.label}  {format_rate(cell.rate)} ({w}x{h})  {cell.total_ms:.0f} ms")
            else:
                strip = Image.new("RGB", (width, layout.caption_height), (0, 0, 0))
                sdraw = ImageDraw.Draw(strip)
                for k, text in enumerate(texts[r][c]):
                    sdraw.text((4, 4 + k * (fs + 4)), text, fill=(255, 255, 255), font=font)
                out.paste(strip, (x, y + height))
            out.paste(tile, (x, y))
    return out


def save_image(path: str | Path, img: Image.Image | np.ndarray, force: bool = False) -> Path:
    """Write a PNG (uint8 RGB) atomically, or for .npy the float array itself."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        arr = np.asarray(img, dtype=np.float32)
        return atomic_write(path, lambda p: np.save(p, arr), force)
    pil = img if isinstance(img, Image.Image) else Image.fromarray(to_uint8(img))
    return atomic_write(path, lambda p: pil.save(p, format="PNG"), force)


@dataclass
class Differences:
    """The difference rows of a comparison: one row of colour-mapped signed differences per rate (`differences`), one
    scale for the whole figure, and each cell's PSNR against the row's reference."""

    kind: str  # a key of DIFFS
    cells: list[list[Cell]]  # rows: rates; rgb: the colour-mapped difference at the render's resolution
    psnr: list[list[float]]
    scale: float
    reference: list[str]  # per rate: what the row is the difference to

    @property
    def title(self) -> str:
        return f"difference (mean over RGB): {DIFFS[self.kind]}"


def difference_rows(renderer: Renderer, camera: Camera, cells: list[list[Cell]], kind: str) -> Differences:
    """Per rate (a row of `cells`), each cell minus the row's first cell ('first') or minus the dense reference at
    that rate ('ref'), colour-mapped with one scale: the largest of the cells' robust scales (so that no cell clips
    more than 1 % of its pixels; the first cell's difference to itself left out)."""
    refs = [
        row[0].rgb
        if kind == "first"
        else reference_image(renderer, camera.at_sampling_rate(row[0].rate), row[0].rate, "dense", row[0].settings)
        for row in cells
    ]
    ds = [[signed_difference(c.rgb, ref) for c in row] for row, ref in zip(cells, refs)]
    scale = max((robust_scale(d) for row in ds for k, d in enumerate(row) if kind == "ref" or k > 0), default=MIN_SCALE)
    return Differences(
        kind,
        [[replace(c, rgb=colour_difference(d, scale)) for c, d in zip(row, drow)] for row, drow in zip(cells, ds)],
        [[psnr(c.rgb, ref) for c in row] for row, ref in zip(cells, refs)],
        scale,
        [row[0].mode_label if kind == "first" else "scalar 8x8" for row in cells],
    )


def colour_bar_strip(width: int, title: str, scale: float, font_size: int) -> tuple[Image.Image, tuple]:
    """A strip `width` wide under a figure: `title`, the colour bar of `colour_difference` at `scale` and its -scale,
    0, +scale labels; and where the bar is in the strip (x, y, w, h)."""
    font = _font(font_size)
    bw, bh = max(2, min(width - 16, 512)), font_size
    x0, y0 = 8, font_size + 10
    strip = Image.new("RGB", (width, y0 + bh + font_size + 12), (0, 0, 0))
    strip.paste(Image.fromarray(to_uint8(colour_bar(bw, bh))), (x0, y0))
    draw = ImageDraw.Draw(strip)
    draw.text((x0, 4), title, fill=(255, 255, 255), font=font)
    for text, x, align in (
        (f"-{format_scale(scale)}", x0, 0.0),
        ("0", x0 + bw / 2, 0.5),
        (f"+{format_scale(scale)}", x0 + bw, 1.0),
    ):
        draw.text((x - align * draw.textlength(text, font=font), y0 + bh + 3), text, fill=(255, 255, 255), font=font)
    return strip, (x0, y0, bw, bh)


@dataclass
class Comparison:
    """A comparison figure and what is in it."""

    image: Image.Image
    cells: list[list[Cell]]  # rows: rates; columns: settings
    psnr: list[list[float | None]]
    layout: GridLayout  # the grid's rows: one per rate, or (with differences) each rate's row then its differences
    diff: Differences | None = None
    bar: tuple[int, int, int, int] | None = None  # (x, y, w, h) of the colour bar in `image`, under the grid

    def origin(self, rate: int, col: int, diff: bool = False) -> tuple[int, int]:
        """(x, y) in `image` of the nearest-upscaled cell of rate `rate` (or of its difference) and column `col`."""
        return self.layout.origin(2 * rate + diff if self.diff is not None else rate, col)


def _psnr_note(p: float | None, reference: str = "") -> str:
    if p is None:
        return "no reference"
    if math.isinf(p):
        return "the row's reference" if reference else "reference"
    return f"PSNR {p:.2f} dB" + (f" vs {reference}" if reference else "")


def compare_figure(
    scene: Scene,
    camera: Camera,
    settings_list: Sequence[RenderSettings],
    rates: Sequence[float],
    backend: str = "cpu",
    inset: tuple[float, float, float, float] | None = None,
    diff: str | None = None,
) -> Comparison:
    """Grid of modes (columns) x rates (rows) like the paper's figures: each cell rendered at camera
    .at_sampling_rate(rate), nearest-upscaled to the camera's size, captioned below with mode, rate and size and
    with its PSNR against the zoom-out reference (`reference_psnr`) and render time. `inset` (x, y, w, h in x1
    pixels) is magnified into each cell's corner. `diff` ('first' or 'ref', see DIFFS and `difference_rows`) adds
    under each rate's row the colour-mapped differences with their PSNRs, and the colour bar under the grid."""
    settings_list, rates = list(settings_list), list(rates)
    if not settings_list or not rates:
        raise GBViewerError("compare: give at least one mode and one rate")
    if diff is not None and diff not in DIFFS:
        raise GBViewerError(f"compare: difference rows {diff!r}; expected one of {', '.join(DIFFS)}")
    cells = render_grid(scene, camera, settings_list, rates, backend)
    ref_settings = RenderSettings(Mode.SCALAR, background=settings_list[0].background)  # plain scalar x1
    ref = next((c.rgb for row in cells for c in row if c.rate == 1.0 and c.settings == ref_settings), None)
    if ref is None and any(r <= 1 for r in rates):
        ref = get_renderer(scene, backend).render(camera, ref_settings).rgb
    psnrs = [[reference_psnr(ref, c.rgb, c.rate) if ref is not None else None for c in row] for row in cells]
    notes = {
        id(c): [
            f"{c.mode_label}  {format_rate(c.rate)} ({c.rgb.shape[1]}x{c.rgb.shape[0]})",
            f"{_psnr_note(p)}  {c.total_ms:.0f} ms",
        ]
        for row, prow in zip(cells, psnrs)
        for c, p in zip(row, prow)
    }
    rows = cells
    diffs = difference_rows(get_renderer(scene, backend), camera, cells, diff) if diff is not None else None
    if diffs is not None:
        rows = [r for pair in zip(cells, diffs.cells) for r in pair]
        notes.update(
            {
                id(c): [f"{c.mode_label} - {name}  {format_rate(c.rate)}", _psnr_note(p, name)]
                for row, prow, name in zip(diffs.cells, diffs.psnr, diffs.reference)
                for c, p in zip(row, prow)
            }
        )
    img = compose_grid(
        rows, camera.width, camera.height, GAP, captions="below", lines=lambda c: notes[id(c)], inset=inset
    )
    fs = caption_font_size(camera.height)
    layout = GridLayout(
        len(rows), len(settings_list), camera.width, camera.height, GAP, GridLayout.caption_height_for(2, fs)
    )
    assert layout.size == img.size
    bar = None
    if diffs is not None:
        strip, (bx, by, bw, bh) = colour_bar_strip(img.width, diffs.title, diffs.scale, fs)
        out = Image.new("RGB", (img.width, img.height + GAP + strip.height), (40, 40, 40))
        out.paste(img, (0, 0))
        out.paste(strip, (0, img.height + GAP))
        img, bar = out, (bx, img.height + GAP + by, bw, bh)
    return Comparison(img, cells, psnrs, layout, diffs, bar)


def write_comparison(
    out: str | Path,
    scene: Scene,
    camera: Camera,
    settings_list: Sequence[RenderSettings],
    rates: Sequence[float],
    backend: str = "cpu",
    inset: tuple[float, float, float, float] | None = None,
    force: bool = False,
    diff: str | None = None,
) -> Comparison:
    """`compare_figure` written to `out` as PNG, atomically; `out` is checked (.png, not overwritten without `force`)
    before anything is rendered."""
    out = refuse_overwrite(out, force)
    if out.suffix.lower() != ".png":
        raise GBViewerError(f"{out}: output must end in .png")
    comparison = compare_figure(scene, camera, settings_list, rates, backend, inset, diff)
    save_image(out, comparison.image, force)
    return comparison
