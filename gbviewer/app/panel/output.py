"""Panel section: the magnifier loupe, screenshots (window and panes), the camera path and the video."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ..camera.recording import VIDEO_CONTAINERS
from ..screenshots import shot_dir
from ..ui.keys import hint
from ..ui.layout import PANEL_W

if TYPE_CHECKING:
    from ..state import AppState


def draw(
    state: AppState,
    screenshot_window: Callable[[], object],
    screenshot_pane: Callable[[int], object],
    open_dialog: Callable[[], None],
) -> None:
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
    draw_camera_path(state, open_dialog)
    draw_video(state)


def draw_camera_path(state: AppState, open_dialog: Callable[[], None]) -> None:
    """Add keyframe, Clear, Export and Import of the camera path (nerfstudio's camera_path.json)."""
    keys = state.path_keys
    if imgui.button("Add keyframe"):
        state.add_keyframe()
    imgui.same_line()
    if imgui.button("Clear##path"):
        keys.clear()
    imgui.same_line()
    if imgui.button("Export") and len(keys):
        state.export_camera_path()
    if imgui.is_item_hovered():
        imgui.set_tooltip("write the camera path as nerfstudio's camera_path.json (ns-render camera-path reads it)")
    imgui.same_line()
    if imgui.button("Import..."):
        open_dialog()
    if imgui.is_item_hovered():
        imgui.set_tooltip("open a nerfstudio camera_path.json (the Open dialog: it is recognised by its content)")
    what = f"from {keys.source.name}" if keys.source else "keyframes"
    imgui.text_disabled(f"camera path: {len(keys)} {what}" if len(keys) else "camera path: none (zoom video)")


def draw_video(state: AppState) -> None:
    """Record zoom video (and its frame count), or its progress and Cancel while it runs."""
    v = state.video
    if v is not None and not v.finished():
        imgui.progress_bar(v.fraction, (PANEL_W - 100, 0), f"video {v.done_frames}/{v.total}")
        imgui.same_line()
        if imgui.button("Cancel"):
            v.cancel()
        return
    along = len(state.path_keys) >= 2
    if imgui.button("Record path video" if along else "Record zoom video"):
        state.record_video()
    if imgui.is_item_hovered():
        what = "along the camera path" if along else "x1 to x1/8 zoom of this view"
        imgui.set_tooltip(f"{what}, one column per pane's mode, rendered in the background")
    imgui.same_line()
    imgui.set_next_item_width(60)
    codecs = list(VIDEO_CONTAINERS)
    ch, k = imgui.combo("##codec", codecs.index(state.video_codec), [f"{c} {VIDEO_CONTAINERS[c][1:]}" for c in codecs])
    if ch:
        state.video_codec = codecs[k]
    if not along:
        imgui.same_line()
        imgui.set_next_item_width(90)
        _, state.video_frames = imgui.slider_int("frames", state.video_frames, 15, 300)
