"""Panel section: the training dataset (Open dataset..., its photo folder, Close dataset, Keep dataset after a scene
change), its views listed by split and name (a click snaps the camera to one), the snapped view, and pane A showing
the photo."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...io.datasets import SPLITS
from ..difference.thread import PHOTO
from ..ui.keys import hint
from ..ui.layout import PANEL_W

if TYPE_CHECKING:
    from ..state import AppState
    from ..ui.dialogs import FileDialogs

LIST_H = 150  # pixels of the views list


def open_dataset_dialog(state: AppState, dialogs: FileDialogs) -> None:
    """The system's folder dialog (or the built-in browser) to open a dataset folder beside the scene."""
    start = (
        state.dataset.dataset.root.parent
        if state.dataset.dataset is not None
        else (state.scene_path.parent if state.scene_path else Path.cwd())
    )
    dialogs.open_folder(start, "Open a dataset folder (COLMAP, Blender or cameras.json)", state.dataset.open)


def draw(state: AppState, dialogs: FileDialogs) -> None:
    ds = state.dataset
    if imgui.button("Open dataset..."):
        open_dataset_dialog(state, dialogs)
    imgui.same_line()
    imgui.set_next_item_width(110)
    _, ds.images = imgui.input_text("photos", ds.images)
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            "the photo folder of a COLMAP capture or a cameras.json (images_4: quarter size; x1 is "
            "the photos' resolution)"
        )
    if ds.loader is not None:
        imgui.text(f"Loading {ds.loader.path.name} ...")
        imgui.progress_bar(-1.0 * ds.loader.elapsed, (PANEL_W - 24, 0), f"{ds.loader.elapsed:.1f} s")
    if ds.error:
        imgui.push_text_wrap_pos(PANEL_W - 16)
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), ds.error)
        imgui.pop_text_wrap_pos()
    if ds.dataset is None:
        if ds.set_aside is not None:
            if imgui.button(f"Keep dataset {ds.set_aside[0].root.name}"):
                state.keep_dataset()
            if imgui.is_item_hovered():
                imgui.set_tooltip("closed with the previous scene; this scene's bounds fit its cameras: reopen it")
        else:
            imgui.text_disabled("no dataset (gbviewer SCENE --data DATASET)")
        return
    d = ds.dataset
    test = sum(v.in_split("test") for v in d.views)
    if imgui.small_button("Close dataset"):
        state.close_dataset()
        return
    imgui.same_line()
    imgui.text(f"{d.root.name}: {d.format}, {len(d.views)} views, {test} test")
    for split in SPLITS:
        if split != SPLITS[0]:
            imgui.same_line()
        if imgui.radio_button(split, ds.split == split):
            ds.set_split(split)
    imgui.same_line(0, 14)
    imgui.set_next_item_width(-1)
    _, ds.name_filter = imgui.input_text_with_hint("##name", "name", ds.name_filter)
    listed = ds.listed()
    imgui.begin_child("views", (0, LIST_H), imgui.ChildFlags_.borders.value)
    for k in listed:
        v = d.views[k]
        if imgui.selectable(f"{v.name}  ({v.split}, {v.camera.width}x{v.camera.height})##{k}", k == ds.index)[0]:
            state.snap_view(k)
    if not listed:
        imgui.text_disabled("(no view of this split with this name)")
    imgui.end_child()
    view = ds.view
    pos = f"{listed.index(ds.index) + 1}/{len(listed)}" if ds.index in listed else f"-/{len(listed)}"
    where = (
        "free camera"
        if view is None
        else (view.name if ds.snapped(state.controller.state()) is not None else f"left {view.name}")
    )
    imgui.text(f"{hint('step_camera', -1)} {hint('step_camera', 1)}  {pos}: {where}")
    a = state.settings.panes[0]
    ch, on = imgui.checkbox("pane A shows the photo", a.view == PHOTO)
    if ch:
        state.set_pane(0, view=PHOTO if on else "color")
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            "the snapped view's photo box-downsampled to the rate (any pane: its view 'photo'); the "
            "other panes' PSNR / SSIM are against it"
        )
