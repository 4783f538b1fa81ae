"""The pixel inspector in the real window (Xvfb, Mesa llvmpipe): Ctrl+click pins a pixel at x1/8 where scalar and
gaussian_blending differ, the Inspector docks below the panes (which shrink and render again: the pin stays on the
same scene point) with one trace per pane, each the colour of the pixel the pane shows; T unpins and closes it.
Screenshots are kept in tests/output/ (viewer-inspector-*.png)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from window_helpers import LABEL_BAND, press, shot, wait

from gbviewer.outputs.figure import to_uint8

pytestmark = pytest.mark.display
TOL = 1e-5


def inspector_rect(app) -> tuple[float, float, float, float] | None:
    """The Inspector window's (x0, y0, x1, y1) when it was drawn last frame, else None."""
    from imgui_bundle.imgui import internal

    w = internal.find_window_by_name("Inspector")
    if w is None or not w.active:
        return None
    return w.pos.x, w.pos.y, w.pos.x + w.size.x, w.pos.y + w.size.y


def wait_traced(app, timeout: float = 120.0) -> None:
    """Until every pane shows its latest request in full and each pane's trace is of the frame it shows, and still
    so two UI frames later (what the test then reads: a frame arriving after the traces makes them stale)."""
    t0 = time.perf_counter()
    while True:
        left = timeout - (time.perf_counter() - t0)
        assert left > 0, "the traces did not come"
        if app.wait_rendered(left) and app.inspector.current():
            app.run_frames(2)
            if app.panes.all_current() and app.inspector.current():
                return
        app.step()
        time.sleep(0.01)


def differing_pixel(a: np.ndarray, b: np.ndarray, top: int) -> tuple[int, int]:
    """(x, y) where two renders differ the most, in the upper half below row `top`, 2 pixels in from the sides."""
    d = np.abs(a - b).max(axis=2)
    h = a.shape[0] // 2
    region = d[top:h, 2:-2]
    y, x = np.unravel_index(np.argmax(region), region.shape)
    return int(x) + 2, int(y) + top


def ctrl_click(app, x: float, y: float) -> None:
    from imgui_bundle import imgui

    io = imgui.get_io()
    io.add_mouse_pos_event(x, y)
    app.step()
    io.add_key_event(imgui.Key.left_ctrl, True)
    io.add_key_event(imgui.Key.mod_ctrl, True)
    app.step()
    io.add_mouse_button_event(0, True)
    app.step()
    io.add_mouse_button_event(0, False)
    io.add_key_event(imgui.Key.left_ctrl, False)
    io.add_key_event(imgui.Key.mod_ctrl, False)
    app.step()


def test_pin_a_pixel_at_x1_8_and_inspect_it(app):
    from imgui_bundle import imgui

    state = app.state
    state.set_pane_count(2)
    state.settings.layout = "row"
    state.set_pane(0, mode="scalar", supersample=1, split=False, view="color")
    state.set_pane(1, mode="gaussian_blending", supersample=1, split=False, view="color")
    state.set_rate(1 / 8)
    wait(app)
    a, b = (state.panes[i].parts["a"].frame for i in range(2))
    assert a.rgb.shape == b.rgb.shape
    x, y = differing_pixel(a.rgb, b.rgb, LABEL_BAND // 8 + 2)
    assert np.abs(a.rgb[y, x] - b.rgb[y, x]).max() > 0.05, "no visible difference to inspect"
    h, w = a.rgb.shape[:2]
    r = state.panes[0].rect
    before = shot(app, "viewer-inspector-before")
    assert inspector_rect(app) is None
    cam = state.panes[0].parts["a"].job.camera
    ctrl_click(app, r.x + (x + 0.5) / w * r.w, r.y + (y + 0.5) / h * r.h)
    assert app.inspector.pin is not None
    wait_traced(app)
    img = shot(app, "viewer-inspector-x1_8")
    box = inspector_rect(app)
    assert box is not None
    # docked below the panes: they shrank to make room, and were rendered again at their new size
    assert state.dock_rect is not None and box[1] >= max(p.rect.y + p.rect.h for p in state.visible)
    a, b = (state.panes[i].parts["a"].frame for i in range(2))
    new = state.panes[0].parts["a"].job.camera
    assert (new.width, new.height) != (cam.width, cam.height)
    h, w = a.rgb.shape[:2]
    entries = app.inspector.entries()
    assert [e.name for e in entries] == ["A", "B"]
    X, Y = entries[0].pixel
    # the pinned pixel is the same point of the scene: its ray is the clicked pixel's within a pixel of either size
    ray = lambda c, px, py: np.array([(px + 0.5 - c.cx) / c.fx, (py + 0.5 - c.cy) / c.fy])  # noqa: E731
    assert np.abs(ray(new, X, Y) - ray(cam, x, y)).max() <= 0.5 / new.fx + 0.5 / cam.fx + 1e-9
    for e, frame in zip(entries, (a, b)):
        assert e.pixel == (X, Y) and e.trace.mode == ("scalar", "gaussian_blending fast")[e.slot[0]]
        np.testing.assert_allclose(e.trace.color, frame.rgb[Y, X], atol=TOL, rtol=0)
        assert abs(e.trace.transmittance - (1 - frame.alpha[Y, X])) <= TOL
        # the pixel itself is on screen as rendered (the outline is drawn around it, the window elsewhere)
        p = state.panes[e.slot[0]].rect
        cx, cy = int(p.x + (X + 0.5) / w * p.w), int(p.y + (Y + 0.5) / h * p.h)
        assert not (box[0] <= cx <= box[2] and box[1] <= cy <= box[3])
        assert np.abs(img[cy, cx].astype(int) - to_uint8(frame.rgb[Y, X]).astype(int)).max() <= 1
        above = img[cy - int(p.h / h) - 3 : cy, cx].astype(int)  # up from its centre: the yellow outline
        assert ((above[:, 0] > 200) & (above[:, 1] > 160) & (above[:, 2] < 120)).any(), above
    bx0, by0, bx1, by1 = (int(v) for v in box)  # the window is drawn where the panes were
    assert np.abs(img[by0:by1, bx0:bx1].astype(int) - before[by0:by1, bx0:bx1]).mean() > 5
    # the slider steps to the top contributor of gaussian_blending: its ellipse highlighted, its window drawn
    insp = app.inspector
    tb = entries[1].trace
    top = insp.order(tb, True)[0]
    insp.options.step[(1, "a")] = top
    app.run_frames(2)
    stepped = shot(app, "viewer-inspector-x1_8-step")
    assert np.abs(stepped[by0:by1, bx0:bx1].astype(int) - img[by0:by1, bx0:bx1]).mean() > 0.1  # B's drawing moved
    # one pane alone, every list entry
    insp.options.alone, insp.options.show_all = (1, "a"), True
    app.run_frames(2)
    shot(app, "viewer-inspector-x1_8-alone")
    # T unpins and closes the window
    press(app, imgui.Key.t)
    assert insp.pin is None and inspector_rect(app) is None
    # T over a pane pins again, Esc unpins
    io = imgui.get_io()
    io.add_mouse_pos_event(r.x + r.w / 2, r.y + r.h * 0.6)
    app.step()
    press(app, imgui.Key.t)
    assert insp.pin is not None and inspector_rect(app) is not None
    press(app, imgui.Key.escape)
    assert insp.pin is None and inspector_rect(app) is None
