"""Panel section: the render backends, greyed out with the reason where one is not usable here, and auto with the
one it picked and why."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...render import AUTO, BACKEND_NAMES
from ..display import describe
from ..layout import PANEL_W

if TYPE_CHECKING:
    from ..state import AppState
    from ..worker import RenderWorker


def draw(state: AppState, worker: RenderWorker) -> None:
    s = state.settings
    for name in BACKEND_NAMES:
        ok, why = worker.backend_status(name)
        imgui.begin_disabled(ok is not True)
        if imgui.radio_button(name, s.backend == name) and ok:
            s.backend = name
        imgui.end_disabled()
        picked = worker.auto if name == AUTO else None
        if ok is not True or picked is not None:
            imgui.same_line()
            imgui.push_text_wrap_pos(PANEL_W - 16)
            if picked is not None:
                imgui.text(f"renders on {picked.name}")
                imgui.text_disabled(picked.reason)
            else:
                imgui.text_disabled(why if len(why) < 140 else why[:137] + "...")
            imgui.pop_text_wrap_pos()
    if worker.backend_status(s.backend)[0] is False:
        imgui.text_colored(imgui.ImVec4(1, 0.8, 0.25, 1),
                           f"{s.backend} unavailable: rendering on {worker.backend_for(s.backend)}")
    path, why = worker.display_path(worker.backend_for(s.backend))
    imgui.text_disabled(f"display: {path}, {describe(path)}")
    if imgui.is_item_hovered():
        imgui.set_tooltip(why)
