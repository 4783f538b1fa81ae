"""The settings panel on the left: one module per section, drawn top to bottom."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ..layout import PANEL_W
from . import backend, camera, dataset, differences, output, panes, rate, scene, timings

if TYPE_CHECKING:
    from ..window import ViewerApp

SECTIONS = (("Scene", scene.draw), ("Dataset", dataset.draw), ("Backend", backend.draw), ("Sampling rate (all panes)", rate.draw),
            ("Panes", panes.draw), ("Difference and error", differences.draw), ("Camera", camera.draw),
            ("Magnifier and output", output.draw), ("Timings", timings.draw))


def draw_panel(app: ViewerApp) -> None:
    v = app.state.viewport
    imgui.set_next_window_pos((0, v.y))
    imgui.set_next_window_size((PANEL_W, v.h))
    flags = (imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_move
             | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_bring_to_front_on_focus).value
    imgui.begin("##panel", None, flags)
    for title, draw in SECTIONS:
        imgui.spacing()
        if imgui.collapsing_header(title, imgui.TreeNodeFlags_.default_open.value):
            draw(app)
    imgui.end()
