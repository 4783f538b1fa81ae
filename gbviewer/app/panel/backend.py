"""Panel section: the render backends on one line, greyed out where one is not usable here (the reason in its
tooltip), what renders (auto's pick) and the display path, each one line with its reason in a tooltip, and the CPU
module's SIMD path (how it was built in the tooltip)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...render import AUTO, BACKEND_NAMES, build_info, compiler_line, simd_line
from ..frames.display import describe

if TYPE_CHECKING:
    from ..state import AppState
    from ..threads.worker import RenderWorker


def draw(state: AppState, worker: RenderWorker) -> None:
    """The backends on one line (an unusable one greyed out, its reason the tooltip), then one line each for what
    renders and the display path (their reasons in tooltips), then the CPU module's SIMD line."""
    s = state.settings
    for k, name in enumerate(BACKEND_NAMES):
        ok, why = worker.backend_status(name)
        if k:
            imgui.same_line()
        imgui.begin_disabled(ok is not True)
        if imgui.radio_button(name, s.backend == name) and ok:
            s.backend = name
        imgui.end_disabled()
        if ok is not True and imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled.value):
            imgui.set_tooltip(f"{name}: {why}")
    used = worker.backend_for(s.backend)
    picked = worker.auto if s.backend == AUTO else None
    if worker.backend_status(s.backend)[0] is False:
        imgui.text_colored(imgui.ImVec4(1, 0.8, 0.25, 1), f"{s.backend} unavailable: rendering on {used}")
        reason = worker.backend_status(s.backend)[1]
    else:
        imgui.text(f"renders on {picked.name if picked is not None else used}")
        reason = picked.reason if picked is not None else f"{used}, as chosen"
    if imgui.is_item_hovered():
        imgui.set_tooltip(reason)
    path, why = worker.display_path(used)
    imgui.same_line()
    imgui.text_disabled(f"| display {path}")
    if imgui.is_item_hovered():
        imgui.set_tooltip(f"{describe(path)}: {why}")
    info = build_info()
    if info["cpu_module"] and not info["scalar_only"] and info["simd_selected"] != "scalar":
        imgui.text_disabled(simd_line(info))
    else:  # scalar by build, by choice (GBVIEWER_SIMD) or no module: said in the warning colour
        imgui.text_colored(imgui.ImVec4(1, 0.8, 0.25, 1), simd_line(info))
    if imgui.is_item_hovered():
        imgui.set_tooltip(compiler_line(info) or info.get("reason", ""))
