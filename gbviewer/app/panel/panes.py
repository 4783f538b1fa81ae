"""Panel section: the number of panes, row or grid, and per pane its mode, supersampling, level of detail, view and
split."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ..frames.views import VIEW_HELP, VIEWS
from ..settings import MAX_PANE_LOD, MODE_NAMES

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState) -> None:
    s = state.settings
    for n in range(1, 5):
        if n > 1:
            imgui.same_line()
        if imgui.radio_button(f"{n}##panes", s.pane_count == n):
            state.set_pane_count(n)
    imgui.same_line(0, 18)
    if imgui.radio_button("row", s.layout == "row"):
        s.layout = "row"
    imgui.same_line()
    if imgui.radio_button("2x2", s.layout == "grid"):
        s.layout = "grid"
    modes = list(MODE_NAMES)
    for p in state.visible:
        ps = s.panes[p.index]
        imgui.push_id(p.index)
        imgui.separator_text(f"Pane {p.name}")
        imgui.set_next_item_width(170)
        ch, k = imgui.combo("mode", modes.index(ps.mode), modes)
        if ch:
            state.set_pane(p.index, mode=modes[k])
        imgui.set_next_item_width(170)
        ch, ss = imgui.slider_int("supersample", ps.supersample, 1, 8, "%dx%d" % (ps.supersample, ps.supersample))
        if ch:
            state.set_pane(p.index, supersample=ss)
        ch, on = imgui.checkbox("LOD", ps.lod > 0)
        if ch:
            state.set_pane(p.index, lod=1.0 if on else 0.0)
        if imgui.is_item_hovered():
            imgui.set_tooltip(
                "draw the splat hierarchy's cut at tau projected pixels, still frames too (off: "
                "previews use a cut while the camera moves, still frames every splat)"
            )
        imgui.same_line()
        imgui.begin_disabled(ps.lod == 0)
        imgui.set_next_item_width(120)
        ch, tau = imgui.slider_float(
            "##lod",
            ps.lod if ps.lod > 0 else 1.0,
            0.25,
            MAX_PANE_LOD,
            "tau %.2f px" if ps.lod > 0 else "off",
            imgui.SliderFlags_.logarithmic.value,
        )
        if ch and ps.lod > 0:
            state.set_pane(p.index, lod=tau)
        imgui.end_disabled()
        imgui.set_next_item_width(170)
        ch, k = imgui.combo("view", VIEWS.index(ps.view), list(VIEWS))
        if ch:
            state.set_pane(p.index, view=VIEWS[k])
        if imgui.is_item_hovered():
            imgui.set_tooltip("\n".join(f"{k}: {v}" for k, v in VIEW_HELP.items()))
        ch, on = imgui.checkbox("split with", ps.split)
        if ch:
            state.set_pane(p.index, split=on)
        imgui.same_line()
        imgui.begin_disabled(not ps.split)
        imgui.set_next_item_width(150)
        ch, k = imgui.combo("##splitmode", modes.index(ps.split_mode), modes)
        if ch:
            state.set_pane(p.index, split_mode=modes[k])
        imgui.end_disabled()
        imgui.pop_id()
