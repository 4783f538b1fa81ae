"""The main menu bar; each item's shortcut hint comes from the key map (`keys.hint`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from .panel.dataset import open_dataset_dialog
from .ui.keys import hint, label

if TYPE_CHECKING:
    from .window import ViewerApp


def _item(text: str, action: str, *args, selected: bool = False, enabled: bool = True) -> bool:
    return imgui.menu_item(text, hint(action, *args), selected, enabled)[0]


def draw_menu(app: ViewerApp) -> None:
    if not imgui.begin_main_menu_bar():
        return
    state, s = app.state, app.state.settings
    if imgui.begin_menu("File"):
        if _item("Open scene or cameras.json...", "open_dialog"):
            app.open_dialog()
        if imgui.menu_item("Open dataset...", "", False)[0]:
            open_dataset_dialog(app.state, app.dialogs)
        if imgui.begin_menu("Open recent", bool(s.recent)):
            for r in s.recent:
                if imgui.menu_item(r, "", False, Path(r).exists())[0]:
                    state.open(r)
            imgui.end_menu()
        imgui.separator()
        if _item("Screenshot of the window", "screenshot_window"):
            app.screenshot_window()
        for p in state.visible:
            if imgui.menu_item(f"Screenshot of pane {p.name} (16-bit, render resolution)", "", False)[0]:
                app.screenshot_pane(p.index)
        imgui.separator()
        if _item("Quit", "quit"):
            app.quit()
        imgui.end_menu()
    if imgui.begin_menu("View"):
        for n in range(1, 5):
            if _item(f"{n} pane{'s' if n > 1 else ''}", "set_pane_count", n, selected=s.pane_count == n):
                state.set_pane_count(n)
        if _item("2x2 grid", "toggle_layout", selected=s.layout == "grid"):
            state.toggle_layout()
        if _item("Magnifier loupe", "toggle_loupe", selected=s.loupe):
            state.toggle_loupe()
        if _item("Information overlay", "toggle_info", selected=s.show_info):
            state.toggle_info()
        if _item("Pixel inspector", "toggle_pin", selected=app.inspector.pin is not None):
            app.inspector.toggle_pin()
        imgui.end_menu()
    if imgui.begin_menu("Camera"):
        if _item("Reset", "reset_camera"):
            state.reset_camera()
        if _item("Fly mode", "toggle_fly", selected=state.fly):
            state.toggle_fly()
        if _item("Orthographic", "toggle_projection", selected=s.projection == "orthographic"):
            state.toggle_projection()
        views = bool(state.cameras) or state.dataset.dataset is not None
        if _item("Next training camera or dataset view", "step_camera", 1, enabled=views):
            state.step_camera(1)
        if _item("Previous training camera or dataset view", "step_camera", -1, enabled=views):
            state.step_camera(-1)
        imgui.end_menu()
    if imgui.begin_menu("Help"):
        if _item("Shortcuts", "toggle_help", selected=state.show_help):
            state.toggle_help()
        imgui.end_menu()
    shortcuts = f"{label('toggle_help')} : shortcuts"
    imgui.same_line(imgui.get_io().display_size.x - imgui.calc_text_size(shortcuts).x - 16)
    imgui.text_disabled(shortcuts)
    imgui.end_main_menu_bar()
