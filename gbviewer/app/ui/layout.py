"""Where things go in the window: pane rectangles (a row or a 2x2 grid, letterboxed to a photo's aspect), the loupe's
texture window, the two parts of a split pane."""

from __future__ import annotations

from dataclasses import dataclass

LAYOUTS = ("row", "grid")
PANEL_W = 340  # the settings panel on the left; the panes fill the rest of the window


@dataclass(frozen=True)
class Rect:
    x: int
    y: int
    w: int
    h: int

    def contains(self, px: float, py: float) -> bool:
        return self.x <= px < self.x + self.w and self.y <= py < self.y + self.h


def grid_shape(n: int, layout: str) -> tuple[int, int]:
    """(rows, cols) for n panes: 'row' puts them side by side, 'grid' 2x2 (for 3 or 4 panes; 1 or 2 stay a row)."""
    if layout == "grid" and n >= 3:
        return 2, 2
    return 1, max(1, n)


def pane_rects(x: int, y: int, w: int, h: int, n: int, layout: str = "row", gap: int = 4) -> list[Rect]:
    """Integer rectangles of n panes filling (x, y, w, h), `gap` pixels apart, row-major."""
    rows, cols = grid_shape(n, layout)
    out = []
    for k in range(n):
        r, c = divmod(k, cols)
        x0 = x + (c * (w + gap)) // cols
        x1 = x + ((c + 1) * (w + gap)) // cols - gap
        y0 = y + (r * (h + gap)) // rows
        y1 = y + ((r + 1) * (h + gap)) // rows - gap
        out.append(Rect(x0, y0, max(1, x1 - x0), max(1, y1 - y0)))
    return out


def fit_aspect(r: Rect, aspect: float) -> Rect:
    """The largest rectangle of `aspect` (width / height) centred in `r` (a pane letterboxed to a photo's shape)."""
    w, h = min(r.w, max(1, round(r.h * aspect))), min(r.h, max(1, round(r.w / aspect)))
    return Rect(r.x + (r.w - w) // 2, r.y + (r.h - h) // 2, w, h)


def loupe_uv(
    u: float, v: float, pane_w: int, pane_h: int, radius_px: float, zoom: float
) -> tuple[float, float, float, float]:
    """Texture rectangle (u0, v0, u1, v1) that a loupe of `radius_px` (display pixels, half its side) magnifying
    `zoom` times shows around the normalised pane position (u, v); kept inside the pane."""
    half_u = radius_px / zoom / pane_w
    half_v = radius_px / zoom / pane_h
    cu = min(max(u, half_u), 1 - half_u) if half_u < 0.5 else 0.5
    cv = min(max(v, half_v), 1 - half_v) if half_v < 0.5 else 0.5
    return cu - half_u, cv - half_v, cu + half_u, cv + half_v


def split_parts(split_pos: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Horizontal texture ranges (u0, u1) of the left (first mode) and right (second mode) parts of a split pane."""
    s = min(1.0, max(0.0, split_pos))
    return (0.0, s), (s, 1.0)


DOCK_BELOW, DOCK_RIGHT, DOCK_RIGHT_MIN = 0.45, 0.36, 360  # the docked inspector's share of the panes' area


def dock_split(v: Rect, side: str | None) -> tuple[Rect, Rect | None]:
    """The panes' area and the docked inspector's (None undocked) when the inspector takes the lower part of the
    viewport `v` ('below') or its right part ('right')."""
    if side == "below":
        h = int(v.h * DOCK_BELOW)
        return Rect(v.x, v.y, v.w, max(1, v.h - h)), Rect(v.x, v.y + v.h - h, v.w, h)
    if side == "right":
        w = min(v.w // 2, max(DOCK_RIGHT_MIN, int(v.w * DOCK_RIGHT)))
        return Rect(v.x, v.y, max(1, v.w - w), v.h), Rect(v.x + v.w - w, v.y, w, v.h)
    return v, None
