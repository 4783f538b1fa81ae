"""What the difference and error views draw over the panes: the colour bar of a colour-mapped difference with its
-scale, 0, +scale labels, below the label and message lines that `overlays` draws (the PSNR/SSIM line is a pane
part's message there)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...outputs.differences import DIVERGING, format_scale
from ..ui.text import PAD
from .labels import WHITE, col, part_box

if TYPE_CHECKING:
    from ..window import ViewerApp

BAR_W, BAR_H = 160, 10


def knot_colours() -> list[int]:
    """DIVERGING's knots as imgui colours: the bar is drawn as one gradient per pair of knots, exactly the map."""
    return [col(*(round(float(c) * 255) for c in rgb)) for rgb in DIVERGING]


def draw_colour_bar(app: ViewerApp, dl, x0: float, y: float, scale: float) -> float:
    """The colour bar at (x0, y) and its labels; the height used."""
    dl.add_rect_filled((x0, y), (x0 + BAR_W + 8, y + BAR_H + 26), col(0, 0, 0, 170), 3.0)
    colours = knot_colours()
    seg = BAR_W / (len(colours) - 1)
    for k in range(len(colours) - 1):
        a, b = colours[k], colours[k + 1]
        dl.add_rect_filled_multi_color((x0 + 4 + k * seg, y + 4), (x0 + 4 + (k + 1) * seg, y + 4 + BAR_H), a, b, b, a)
    if app.mono is not None:
        imgui.push_font(app.mono, 15.0)
    for label, u, align in (
        (f"-{format_scale(scale)}", 0.0, 0.0),
        ("0", 0.5, 0.5),
        (f"+{format_scale(scale)}", 1.0, 1.0),
    ):
        w = imgui.calc_text_size(label).x
        dl.add_text((x0 + 4 + u * BAR_W - align * w, y + BAR_H + 6), WHITE, label)
    if app.mono is not None:
        imgui.pop_font()
    return BAR_H + 30


def draw_analysis_overlays(app: ViewerApp) -> None:
    """Each colour-mapped pane part's colour bar, under its label and message lines (`overlays` placed them and
    left `app.part_tops`), where its box has room."""
    state, analysis = app.state, app.analysis
    if state.scene is None:
        return
    dl = imgui.get_background_draw_list()
    for p in state.visible:
        ps = state.settings.panes[p.index]
        for part in state.parts(p.index):
            scale = analysis.shown_scale.get((p.index, part))
            top = app.part_tops.get((p.index, part))
            box = part_box(p.rect, ps.split, ps.split_pos, part)
            if scale is None or not p.parts[part].view or top is None:
                continue
            if box.w >= BAR_W + 16 and top + BAR_H + 30 <= box.y + box.h:
                draw_colour_bar(app, dl, box.x + PAD, top, scale)
