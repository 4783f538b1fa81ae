"""Panel section: the sampling rate of all panes (a button per step, a log2 slider) and the render sizes."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...model.camera import format_rate
from ..frames.rates import RATE_STEPS, rate_to_slider, slider_to_rate
from ..ui.layout import PANEL_W

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState) -> None:
    s = state.settings
    for k, r in enumerate(RATE_STEPS):
        if k:
            imgui.same_line(0, 3)
        active = abs(s.rate - r) < 1e-9
        if active:
            imgui.push_style_color(imgui.Col_.button.value, imgui.ImVec4(0.24, 0.47, 0.80, 1))
        if imgui.button(format_rate(r), (38, 0)):
            state.set_rate(r)
        if active:
            imgui.pop_style_color()
    imgui.set_next_item_width(PANEL_W - 24)
    changed, val = imgui.slider_float("##rate", rate_to_slider(s.rate), -3.0, 3.0, format_rate(s.rate))
    if changed:
        state.set_rate(slider_to_rate(val))
    sizes = ", ".join(f"{p.name} {p.render_size[0]}x{p.render_size[1]}" for p in state.visible)
    imgui.push_text_wrap_pos(PANEL_W - 16)
    imgui.text_disabled(f"render: {sizes}")
    imgui.pop_text_wrap_pos()
