"""Panel section: the difference and error views (the reference, the colour-map scale, PSNR/SSIM on the panes) and
every pane part's PSNR/SSIM against the reference."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...outputs.differences import ROBUST_PERCENTILE
from ..difference.views import REFERENCE_KINDS
from ..ui.keys import hint

if TYPE_CHECKING:
    from ..difference.views import PaneAnalysis
    from ..state import AppState


def draw(state: AppState, analysis: PaneAnalysis) -> None:
    o = analysis.options
    imgui.text_disabled(f"{hint('toggle_difference')}: pane - pane A   {hint('toggle_error')}: pane - reference")
    kinds = list(REFERENCE_KINDS)
    imgui.set_next_item_width(220)
    ch, k = imgui.combo("reference", kinds.index(o.reference), [f"{n}: {REFERENCE_KINDS[n]}" for n in kinds])
    if ch:
        analysis.set_reference(kinds[k])
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            "box: the x1 scalar render box-downsampled by k at rate 1/k (what gbviewer bench uses)\n"
            "dense: scalar with 8x8 supersampling at the current rate (any rate, 64x the work)\n"
            "photo: the snapped dataset view's photo box-downsampled to the rate (x1/k; snapping to a "
            "view chooses it)"
        )
    ch, on = imgui.checkbox(f"PSNR / SSIM on the panes ({hint('toggle_fidelity')})", o.fidelity)
    if ch:
        analysis.toggle_fidelity()
    ch, auto = imgui.checkbox(f"scale: robust max |d| ({ROBUST_PERCENTILE:g}th percentile)", o.auto_scale)
    if ch:
        analysis.set_scale(auto)
    imgui.begin_disabled(o.auto_scale)
    imgui.set_next_item_width(220)
    ch, lg = imgui.slider_float("fixed scale", math.log10(o.scale), -3.0, 0.0, f"{o.scale:.3g}")
    if ch:
        analysis.set_scale(False, 10**lg)
    imgui.end_disabled()
    for p in state.visible:
        for part in state.parts(p.index):
            line = analysis.fidelity_line((p.index, part))
            if line is None:
                continue
            name = p.name + ("'" if part == "b" else "")
            if line[1]:
                imgui.push_style_color(imgui.Col_.text.value, imgui.get_style().color_(imgui.Col_.text_disabled.value))
            imgui.text_wrapped(f"{name}: {line[0]}")
            if line[1]:
                imgui.pop_style_color()
