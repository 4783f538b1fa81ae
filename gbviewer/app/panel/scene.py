"""Panel section: the open scene, loading progress, the last load error, Open... and the recent files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ..ui.layout import PANEL_W

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState, open_dialog: Callable[[], None]) -> None:
    if state.scene is not None:
        imgui.text(state.scene_path.name if state.scene_path else "?")
        imgui.text_disabled(
            f"{state.scene.num_splats:,} splats, SH degree {state.scene.sh_degree}, "
            f"{state.scene.meta.get('format', '?')}"
        )
    if state.loader is not None:
        ld = state.loader
        imgui.text(f"Loading {ld.path.name}")
        fraction = ld.fraction  # None until the load reports: a bar that moves with the time instead
        imgui.progress_bar(-1.0 * ld.elapsed if fraction is None else fraction, (PANEL_W - 24, 0), ld.describe())
        if imgui.small_button("Cancel"):
            state.cancel_load()
        imgui.same_line()
        imgui.text_disabled(f"{ld.elapsed:.1f} s (Esc cancels)")
    if state.load_error:
        imgui.push_text_wrap_pos(PANEL_W - 16)
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), state.load_error)
        imgui.pop_text_wrap_pos()
        if imgui.small_button("dismiss"):
            state.load_error = ""
    if imgui.button("Open..."):
        open_dialog()
    imgui.same_line()
    if imgui.begin_combo("##recent", "Recent files"):
        recent = state.settings.recent
        for r in recent:
            if imgui.selectable(r, False, 0 if Path(r).exists() else imgui.SelectableFlags_.disabled.value)[0]:
                state.open(r)
        if not recent:
            imgui.text_disabled("(none yet)")
        imgui.end_combo()
