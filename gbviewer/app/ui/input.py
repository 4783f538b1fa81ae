"""Mouse and keyboard: the camera gestures, the split divider and Ctrl+click (pin a pixel) on the panes, and the keys of
`keys.KEYS`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from .keys import KEYS

if TYPE_CHECKING:
    from ..window import ViewerApp

SPLIT_GRAB_PX = 7  # how close to the divider a click grabs it


def handle_input(app: ViewerApp) -> None:
    """This frame's mouse and keys (keys not while a text field has the keyboard)."""
    handle_mouse(app)
    if not imgui.get_io().want_text_input:
        handle_keys(app)


def handle_mouse(app: ViewerApp) -> None:
    io = imgui.get_io()
    state = app.state
    mx, my = io.mouse_pos.x, io.mouse_pos.y
    over = state.pane_at(mx, my) if not io.want_capture_mouse else None
    if over is not None:
        r = state.panes[over].rect
        state.hover = (over, (mx - r.x) / r.w, (my - r.y) / r.h)
    elif not io.want_capture_mouse:
        state.hover = None
    if over is not None and io.key_ctrl and imgui.is_mouse_clicked(0):  # Ctrl+click: inspect this pixel
        app.inspector.pin_at(*state.hover)
    panes = state.settings.panes
    if state.dragging_split is not None:
        if imgui.is_mouse_down(0):
            r = state.panes[state.dragging_split].rect
            state.set_pane(state.dragging_split, split_pos=(mx - r.x) / r.w)
        else:
            state.dragging_split = None
    elif over is not None and imgui.is_mouse_clicked(0) and panes[over].split:
        r = state.panes[over].rect
        if abs(mx - (r.x + panes[over].split_pos * r.w)) <= SPLIT_GRAB_PX:
            state.dragging_split = over
    dragging_view = (
        any(imgui.is_mouse_dragging(b, 0.0) for b in (0, 1, 2))
        and state.hover is not None
        and not io.want_capture_mouse
    )
    if over is None and not dragging_view:
        return
    c = state.controller
    dx, dy = io.mouse_delta.x, io.mouse_delta.y
    if state.dragging_split is None and imgui.is_mouse_dragging(0, 0.0) and (dx or dy):
        (c.look if state.fly else c.orbit)(dx, dy)
        state.moved()
    if (imgui.is_mouse_dragging(1, 0.0) or imgui.is_mouse_dragging(2, 0.0)) and (dx or dy):
        c.pan(dx, dy, state.panes[0].rect.h)
        state.moved()
    if io.mouse_wheel and over is not None:
        c.dolly(io.mouse_wheel)
        state.moved()


def handle_keys(app: ViewerApp) -> None:
    """Run the action of every key of the table pressed this frame (in table order), then move while flying."""
    io = imgui.get_io()
    shift, ctrl = io.key_shift, io.key_ctrl
    flying = [0.0, 0.0, 0.0]
    for k in KEYS:
        if (k.shift is not None and k.shift != shift) or (k.ctrl is not None and k.ctrl != ctrl):
            continue
        key = getattr(imgui.Key, k.key)
        if k.held:
            if imgui.is_key_down(key):
                flying = [a + b for a, b in zip(flying, k.args)]
        elif imgui.is_key_pressed(key, k.repeat):
            app.action(k.action)(*k.args)
    app.state.fly_move(*flying, io.delta_time, shift)
