"""What the difference and error views draw over the panes: the colour bar of a colour-mapped difference with its
-scale, 0, +scale labels, and each pane part's PSNR/SSIM against the chosen reference (grey while stale), below the
pane label and legend that `overlays` draws."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ..differences import DIVERGING, format_scale
from .overlays import GREY, WHITE, col, text

if TYPE_CHECKING:
    from .window import ViewerApp

TOP = 82  # below the label (y + 4), the preview / rendering line (+30) and the legend (+56)
BAR_W, BAR_H = 160, 10


def knot_colours() -> list[int]:
    """DIVERGING's knots as imgui colours: the bar is drawn as one gradient per pair of knots, exactly the map."""
    return [col(*(round(float(c) * 255) for c in rgb)) for rgb in DIVERGING]


def draw_colour_bar(app: ViewerApp, dl, x: float, y: float, scale: float, right: bool = False) -> float:
    """The colour bar at (x, y) (its right edge at x with `right`) and its labels; the height used."""
    x0 = x - BAR_W - 8 if right else x
    dl.add_rect_filled((x0, y), (x0 + BAR_W + 8, y + BAR_H + 26), col(0, 0, 0, 170), 3.0)
    colours = knot_colours()
    seg = BAR_W / (len(colours) - 1)
    for k in range(len(colours) - 1):
        a, b = colours[k], colours[k + 1]
        dl.add_rect_filled_multi_color((x0 + 4 + k * seg, y + 4), (x0 + 4 + (k + 1) * seg, y + 4 + BAR_H), a, b, b, a)
    if app.mono is not None:
        imgui.push_font(app.mono, 15.0)
    for label, u, align in ((f"-{format_scale(scale)}", 0.0, 0.0), ("0", 0.5, 0.5),
                            (f"+{format_scale(scale)}", 1.0, 1.0)):
        w = imgui.calc_text_size(label).x
        dl.add_text((x0 + 4 + u * BAR_W - align * w, y + BAR_H + 6), WHITE, label)
    if app.mono is not None:
        imgui.pop_font()
    return BAR_H + 30


def draw_analysis_overlays(app: ViewerApp) -> None:
    state, analysis = app.state, app.analysis
    if state.scene is None:
        return
    dl = imgui.get_background_draw_list()
    for p in state.visible:
        r = p.rect
        dl.push_clip_rect((r.x, r.y), (r.x + r.w, r.y + r.h), True)
        for part in state.parts(p.index):
            right = part == "b"
            x, y = (r.x + r.w - 4 if right else r.x + 4), r.y + TOP
            scale = analysis.shown_scale.get((p.index, part))
            if scale is not None and p.parts[part].view:
                y += draw_colour_bar(app, dl, x, y, scale, right)
            line = analysis.fidelity_line((p.index, part))
            if line is not None:  # a split's second line one row lower: long lines of both sides would overlap
                text(app, dl, x, y + 22 * right, line[0], GREY if line[1] else WHITE, align_right=right)
        dl.pop_clip_rect()
