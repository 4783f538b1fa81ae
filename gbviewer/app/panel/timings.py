"""Panel section: per pane part the time of each stage of its last render and its renders per second."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ..panes import pane_fps

if TYPE_CHECKING:
    from ..pane_state import RateMeter
    from ..state import AppState
    from ..threads.worker import RenderWorker


def draw(state: AppState, worker: RenderWorker, ui_fps: RateMeter) -> None:
    flags = (imgui.TableFlags_.borders_inner_h | imgui.TableFlags_.row_bg | imgui.TableFlags_.sizing_fixed_fit).value
    if not imgui.begin_table("stats", 6, flags):
        return
    for h in ("", "total", "pre", "sort", "blend", "fps"):
        imgui.table_setup_column(h)
    imgui.table_headers_row()
    for p in state.visible:
        for part in state.parts(p.index):
            frame = p.parts[part].frame
            if frame is None:
                continue
            st = frame.stats
            imgui.table_next_row()
            cells = (
                p.name + ("'" if part == "b" else ""),
                f"{st.total_ms:.0f}",
                f"{st.preprocess_ms:.1f}",
                f"{st.sort_ms:.1f}",
                f"{st.blend_ms:.0f}",
                f"{pane_fps(p, part):.1f}",
            )
            for c in cells:
                imgui.table_next_column()
                imgui.text(c)
    imgui.end_table()
    imgui.text_disabled("ms per stage; fps = finished renders per second")
    imgui.text_disabled(
        f"UI {ui_fps.rate():.0f} fps, {worker.dropped} stale requests dropped, {worker.cancelled} stale renders stopped"
    )
