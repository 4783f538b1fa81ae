"""Panel section: reset, fly mode, projection, field of view, up axis, fly speed, training cameras."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ...model.camera import UP_AXES
from ..camera.control import CameraController
from ..ui.keys import hint

if TYPE_CHECKING:
    from ..state import AppState


def draw(state: AppState, open_dialog: Callable[[], None]) -> None:
    s = state.settings
    if imgui.button(f"Reset ({hint('reset_camera')})"):
        state.reset_camera()
    imgui.same_line()
    _, state.fly = imgui.checkbox(f"fly mode ({hint('toggle_fly')})", state.fly)
    if imgui.checkbox(f"orthographic ({hint('toggle_projection')})", s.projection == "orthographic")[0]:
        state.toggle_projection()
    imgui.set_next_item_width(170)
    ch, fov = imgui.slider_float(
        "field of view", state.controller.fov_y_deg, CameraController.MIN_FOV, CameraController.MAX_FOV, "%.0f deg"
    )
    if ch:
        state.set_fov(fov)
    axes = list(UP_AXES)
    imgui.set_next_item_width(170)
    ch, k = imgui.combo(f"up axis ({hint('next_up')})", axes.index(s.up), axes)
    if ch:
        state.set_up(axes[k])
    if state.fly:
        imgui.set_next_item_width(170)
        _, s.fly_speed = imgui.slider_float(
            "fly speed", s.fly_speed, 0.05, 5.0, "%.2f radii/s", imgui.SliderFlags_.logarithmic.value
        )
    if state.dataset.dataset is not None:
        imgui.text_disabled(f"{hint('step_camera', -1)} {hint('step_camera', 1)} step the dataset's views (Dataset)")
    elif state.cameras:
        if imgui.arrow_button("##prev", imgui.Dir.left):
            state.step_camera(-1)
        imgui.same_line()
        if imgui.arrow_button("##next", imgui.Dir.right):
            state.step_camera(1)
        imgui.same_line()
        cur = state.cameras[state.cam_index].name if state.cam_index >= 0 else "free camera"
        imgui.text(f"training {state.cam_index + 1}/{len(state.cameras)}: {cur}")
    else:
        imgui.text_disabled("no training cameras (cameras.json)")
    if imgui.small_button("Open cameras.json..."):
        open_dialog()
