"""Panel section: the magnifier loupe, screenshots (window and panes) and the zoom video."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ..keys import hint
from ..layout import PANEL_W
from ..screenshots import shot_dir

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState, screenshot_window: Callable[[], object], screenshot_pane: Callable[[int], object]) -> None:
    s = state.settings
    _, s.loupe = imgui.checkbox(f"loupe ({hint('toggle_loupe')})", s.loupe)
    imgui.same_line()
    imgui.set_next_item_width(120)
    _, s.loupe_zoom = imgui.slider_float("zoom", s.loupe_zoom, 2.0, 32.0, "x%.0f")
    if imgui.button(f"Screenshot window ({hint('screenshot_window')})"):
        screenshot_window()
    for p in state.visible:
        if p.index:
            imgui.same_line(0, 4)
        if imgui.button(p.name):
            screenshot_pane(p.index)
        if imgui.is_item_hovered():
            imgui.set_tooltip(f"pane {p.name}: 16-bit PNG at its render resolution")
    imgui.text_disabled(f"into {shot_dir(state)}")
    draw_video(state)


def draw_video(state: AppState) -> None:
    """Record zoom video (and its frame count), or its progress and Cancel while it runs."""
    v = state.video
    if v is not None and not v.finished():
        imgui.progress_bar(v.fraction, (PANEL_W - 100, 0), f"video {v.done_frames}/{v.total}")
        imgui.same_line()
        if imgui.button("Cancel"):
            v.cancel()
        return
    if imgui.button("Record zoom video"):
        state.record_video()
    if imgui.is_item_hovered():
        imgui.set_tooltip("x1 to x1/8 zoom of this view, one column per pane's mode (H.264 MP4), rendered in "
                          "the background")
    imgui.same_line()
    imgui.set_next_item_width(110)
    _, state.video_frames = imgui.slider_int("frames", state.video_frames, 15, 300)
