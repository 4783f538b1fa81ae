"""The settings panel on the left: one module per section, drawn top to bottom."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ..layout import PANEL_W
from . import backend, camera, dataset, differences, output, panes, rate, scene, timings

if TYPE_CHECKING:
    from ..window import ViewerApp


def sections(app: ViewerApp) -> tuple[tuple[str, Callable[[], None]], ...]:
    """The sections top to bottom, each drawer given the state and only the services it uses."""
    s = app.state
    return (("Scene", partial(scene.draw, s, app.open_dialog)), ("Dataset", partial(dataset.draw, s, app.dialogs)),
            ("Backend", partial(backend.draw, s, app.worker)), ("Sampling rate (all panes)", partial(rate.draw, s)),
            ("Panes", partial(panes.draw, s)), ("Difference and error", partial(differences.draw, s, app.analysis)),
            ("Camera", partial(camera.draw, s, app.open_dialog)),
            ("Magnifier and output", partial(output.draw, s, app.screenshot_window, app.screenshot_pane)),
            ("Timings", partial(timings.draw, s, app.worker, app.ui_fps)))


def draw_panel(app: ViewerApp) -> None:
    v = app.state.viewport
    imgui.set_next_window_pos((0, v.y))
    imgui.set_next_window_size((PANEL_W, v.h))
    flags = (imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_move
             | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_bring_to_front_on_focus).value
    imgui.begin("##panel", None, flags)
    for title, draw in sections(app):
        imgui.spacing()
        if imgui.collapsing_header(title, imgui.TreeNodeFlags_.default_open.value):
            draw()
    imgui.end()
