"""The settings panel on the left: one module per section, drawn top to bottom."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ..ui.layout import PANEL_W
from . import backend, background, camera, dataset, differences, output, panes, rate, scene, timings

if TYPE_CHECKING:
    from ..window import ViewerApp


def sections(app: ViewerApp) -> tuple[tuple[str, Callable[[], None]], ...]:
    """The sections top to bottom, in the order a user needs them (scene, panes, rate, views, dataset), each drawer
    given the state and only the services it uses."""
    s = app.state
    return (
        ("Scene", partial(scene.draw, s, app.open_dialog)),
        ("Panes", partial(panes.draw, s)),
        ("Sampling rate (all panes)", partial(rate.draw, s)),
        ("Difference and error", partial(differences.draw, s, app.analysis)),
        ("Dataset", partial(dataset.draw, s, app.dialogs)),
        ("Background", partial(background.draw, s)),
        ("Camera", partial(camera.draw, s, app.open_dialog)),
        ("Magnifier and output", partial(output.draw, s, app.screenshot_window, app.screenshot_pane, app.open_dialog)),
        ("Backend", partial(backend.draw, s, app.worker)),
        ("Timings", partial(timings.draw, s, app.worker, app.ui_fps)),
    )


def draw_panel(app: ViewerApp) -> None:
    v = app.state.viewport
    imgui.set_next_window_pos((0, v.y))
    imgui.set_next_window_size((PANEL_W, v.h))
    flags = (
        imgui.WindowFlags_.no_title_bar
        | imgui.WindowFlags_.no_resize
        | imgui.WindowFlags_.no_move
        | imgui.WindowFlags_.no_collapse
        | imgui.WindowFlags_.no_bring_to_front_on_focus
    ).value
    imgui.begin("##panel", None, flags)
    for title, draw in sections(app):
        imgui.spacing()
        if imgui.collapsing_header(title, imgui.TreeNodeFlags_.default_open.value):
            draw()
    imgui.end()
