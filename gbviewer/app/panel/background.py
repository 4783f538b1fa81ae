"""Panel section: the panes' background, a colour (saved) or, with a dataset open, its photos' backdrop (the median
colour of their borders), and what that estimate found."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ..background import FIXED, PHOTOS

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState) -> None:
    backdrop = state.dataset.backdrop
    if imgui.radio_button("colour", state.background_source == FIXED):
        state.set_background(state.settings.background)
    imgui.same_line()
    ch, rgb = imgui.color_edit3("##background", list(state.settings.background), imgui.ColorEditFlags_.float.value)
    if ch:
        state.set_background(rgb)
    imgui.begin_disabled(backdrop is None)
    if imgui.radio_button("from photos", state.background_source == PHOTOS and backdrop is not None):
        state.use_photo_background()
    imgui.end_disabled()
    imgui.same_line()
    if backdrop is None:
        imgui.text_disabled("(open a dataset)")
    else:
        imgui.color_button("##backdrop", imgui.ImVec4(*backdrop.colour, 1.0))
        imgui.same_line()
        imgui.text_disabled(f"found {backdrop.describe().split(',')[0]}")
        if imgui.is_item_hovered():
            imgui.set_tooltip(
                f"{backdrop.describe()}; the default for opaque photos: a render on another colour "
                "than the photos' backdrop reads a low PSNR however good the scene is"
            )
