"""The pixel inspector without a window: a pin maps to the render pixel each pane draws under it (every rate, split
panes, HiDPI), the trace thread (newest request per pane part wins; its traces are gb.trace_pixel's), the inspector's
traces equal to the pixels the panes show, and the JSON and CSV exports."""

from __future__ import annotations

import csv
import json
import threading
import time

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.frames.rates import RATE_STEPS
from gbviewer.app.inspector.state import (
    Inspector,
    TraceRequest,
    TraceThread,
    ellipse_points,
    pixel_box,
    render_pixel,
    snap,
)
from gbviewer.app.settings import AppSettings
from gbviewer.app.state import AppState
from gbviewer.app.threads.worker import RenderJob
from gbviewer.outputs.figure import upscale_nearest
from gbviewer.outputs.trace_report import CSV_COLUMNS

TOL = 1e-5


def wait_until(done, timeout: float = 60.0) -> None:
    t0 = time.perf_counter()
    while not done():
        assert time.perf_counter() - t0 < timeout, "timed out"
        time.sleep(0.005)


def show_final(state: AppState, i: int, part: str, camera: gb.Camera, frame, settings=None) -> None:
    """Pane i's part shows `frame` as its final frame, rendered at `camera`."""
    shown = state.panes[i].parts[part]
    shown.frame, shown.stage = frame, "final"
    shown.job = RenderJob(
        (i, part),
        state.scene,
        camera,
        settings or state.settings_for(i, part),
        info={"preview": 1.0, "rate": state.settings.rate},
    )


@pytest.fixture(scope="module")
def zoomed_out(bundled_scene) -> gb.Camera:
    """The bundled scene at x1/8 of a 640x480 orbit view: 80x60 pixels."""
    return gb.orbit_camera(bundled_scene, 30, 20, width=640, height=480).at_sampling_rate(1 / 8)


@pytest.fixture
def idle_thread():
    """A trace thread that is never asked (the mapping tests look at the pixels only)."""
    t = TraceThread(trace=lambda req: None)
    yield t
    t.stop()


@pytest.mark.parametrize("scale", [1.0, 2.0])
@pytest.mark.parametrize("panes,layout", [(1, "row"), (2, "row"), (3, "grid"), (4, "grid")])
def test_a_pin_maps_to_the_render_pixel_drawn_under_it(idle_thread, panes, layout, scale):
    state = AppState(AppSettings())
    state.scene = object()
    state.set_pane_count(panes)
    state.settings.layout = layout
    state.set_pane(0, split=True, split_pos=0.4)
    insp = Inspector(state, idle_thread)
    for rate in RATE_STEPS:
        state.set_rate(rate)
        state.layout(1300, 820, 22, 28, (scale, scale))
        for pin in [(0, 0.0, 0.0), (panes - 1, 0.37, 0.81), (0, 0.999, 0.5)]:
            insp.pin_at(*pin)
            u, v = insp.pin
            r0 = state.panes[pin[0]].rect
            fw0 = round(r0.w * scale)  # the pin is at the centre of the framebuffer pixel it was put on
            assert (u * fw0) % 1 == pytest.approx(0.5) and abs(u - pin[1]) <= 0.5 / fw0
            for p in state.visible:
                cam = state.pane_camera(p.index)
                assert (cam.width, cam.height) == p.render_size
                for part in state.parts(p.index):
                    show_final(state, p.index, part, cam, object())
                    x, y = xy = insp.pixel(p.index, part)
                    assert xy == render_pixel(u, v, cam.width, cam.height)
                    r = p.rect
                    x0, y0, x1, y1 = pixel_box(r, x, y, cam.width, cam.height)
                    px, py, eps = r.x + u * r.w, r.y + v * r.h, 1e-6  # (zoomed in: maybe on its edge)
                    assert x0 - eps <= px <= x1 + eps and y0 - eps <= py <= y1 + eps
                    assert (x1 - x0) * scale * rate == pytest.approx(1.0, rel=0.05)  # x1/8: 8x8 display pixels
                    # the nearest upscale to the pane's framebuffer pixels (what the pane blit draws) puts it there
                    fw, fh = round(r.w * scale), round(r.h * scale)
                    ids = np.arange(cam.width * cam.height).reshape(cam.height, cam.width)
                    up = upscale_nearest(ids, fh, fw)
                    assert up[int(v * fh), int(u * fw)] == y * cam.width + x


def ray(cam: gb.Camera, u: float, v: float) -> np.ndarray:
    """The image-plane direction of pane-relative (u, v) of `cam`'s image."""
    return np.array([(u * cam.width - cam.cx) / cam.fx, (v * cam.height - cam.cy) / cam.fy])


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
@pytest.mark.parametrize("panes,layout,dock", [(1, "row", "right"), (2, "row", "below"), (4, "grid", "below")])
def test_the_docked_inspector_shrinks_the_panes_and_the_pin_keeps_its_scene_point(
    idle_thread, panes, layout, dock, projection
):
    state = AppState(AppSettings())
    state.scene = object()
    state.set_pane_count(panes)
    state.settings.layout = layout
    state.controller.projection = projection
    state.set_rate(1 / 4)
    insp = Inspector(state, idle_thread)
    state.layout(1600, 900, 22, 28)
    assert state.dock_rect is None
    insp.pin_at(0, 0.3, 0.7)
    before, pin = state.pane_camera(0), insp.pin
    state.layout(1600, 900, 22, 28, dock=dock)
    insp.follow()
    d, v = state.dock_rect, state.viewport
    assert d is not None and v.x <= d.x and d.x + d.w <= v.x + v.w and v.y <= d.y and d.y + d.h <= v.y + v.h
    assert (d.w == v.w) == (dock == "below") and (d.h == v.h) == (dock == "right")
    for p in state.visible:  # the panes make room
        assert not (
            p.rect.x < d.x + d.w and d.x < p.rect.x + p.rect.w and p.rect.y < d.y + d.h and d.y < p.rect.y + p.rect.h
        )
    after = state.pane_camera(0)
    assert (after.width, after.height) != (before.width, before.height) and insp.pin != pin
    np.testing.assert_allclose(ray(after, *insp.pin), ray(before, *pin), rtol=0, atol=1e-12)
    state.layout(1600, 900, 22, 28)  # undocked again: back where it was
    insp.follow()
    np.testing.assert_allclose(insp.pin, pin, rtol=0, atol=1e-12)
    pin = insp.pin
    state.controller.orbit(40, 10)  # another view: the pin stays where it is on the pane
    state.layout(1600, 900, 22, 28, dock=dock)
    insp.follow()
    assert insp.pin == pin


def test_snap_render_pixel_and_ellipse_points(bundled_scene, zoomed_out):
    assert snap(0.0, 10) == 0.05 and snap(0.999, 10) == 0.95 and snap(1.0, 10) == 0.95
    assert render_pixel(0.5, 0.99, 8, 4) == (4, 3) and render_pixel(1.0, 1.0, 8, 4) == (7, 3)
    trace = gb.trace_pixel(bundled_scene, zoomed_out, 40, 30, "gaussian_blending")
    added = [s for s in trace.steps if not s.rejected]
    assert added
    for s in added:
        pts = ellipse_points(s.mean, s.covariance, s.cutoff)
        d = pts - np.asarray(s.mean)
        a, b, c = s.conic
        q = a * d[:, 0] ** 2 + 2 * b * d[:, 0] * d[:, 1] + c * d[:, 1] ** 2
        np.testing.assert_allclose(q, s.cutoff**2, rtol=1e-4)
    assert ellipse_points((0, 0), (1, 0, -1), 3) is None and ellipse_points((0, 0), (np.inf, 0, 1), 3) is None


def test_the_newest_request_per_pane_part_wins():
    entered, release, calls = threading.Event(), threading.Event(), []

    def trace(req: TraceRequest):
        calls.append(req)
        entered.set()
        release.wait(30)
        return None

    t = TraceThread(trace)
    try:
        reqs = [
            TraceRequest(slot, None, None, None, None, k, 0)
            for k, slot in enumerate([(0, "a"), (0, "a"), (0, "a"), (1, "a"), (0, "a")])
        ]
        t.submit(reqs[0])
        assert entered.wait(30)
        for r in reqs[1:]:  # (0, a) waits three times: only the last stays, behind (1, a) which waited longer
            t.submit(r)
        assert t.busy()
        release.set()
        results = []
        wait_until(lambda: results.extend(t.results()) or len(results) == 3)
        assert calls == [reqs[0], reqs[3], reqs[4]] and [res.request for res in results] == calls
        assert not t.busy() and t.done == 3 and t.results() == []
    finally:
        release.set()
        t.stop()


def test_the_thread_traces_as_gb_trace_pixel(bundled_scene, zoomed_out):
    cam = zoomed_out
    t = TraceThread()
    try:
        cases = [
            ("scalar", 1, 40, 30),
            ("gaussian_blending", 1, 40, 30),
            ("analytic", 2, 12, 20),
            ("duplex", 1, 50, 33),
        ]
        for k, (mode, n, x, y) in enumerate(cases):
            t.submit(TraceRequest(k, bundled_scene, None, cam, gb.RenderSettings(mode, n), x, y))
        results = []
        wait_until(lambda: results.extend(t.results()) or len(results) == len(cases))
        for res in results:
            mode, n, x, y = cases[res.request.slot]
            assert (
                res.error == "" and res.trace.to_json() == gb.trace_pixel(bundled_scene, cam, x, y, mode, n).to_json()
            )
    finally:
        t.stop()


@pytest.fixture
def inspected(bundled_scene, tmp_path):
    """Panes A (scalar, split with mip) and B (gaussian_blending, 2x2) at x1/8 showing their final frames, the
    camera still; an Inspector on them."""
    state = AppState(AppSettings(screenshot_dir=str(tmp_path)))
    state.scene = bundled_scene
    state.set_pane_count(2)
    state.set_pane(0, mode="scalar", split=True, split_mode="mip")
    state.set_pane(1, mode="gaussian_blending", supersample=2)
    state.set_rate(1 / 8)
    state.layout(1300, 820, 22, 28)
    state.last_move = 0.0
    for p in state.visible:
        cam = state.pane_camera(p.index)
        for part in state.parts(p.index):
            settings = state.settings_for(p.index, part)
            show_final(
                state, p.index, part, cam, gb.render(bundled_scene, cam, settings.mode, settings.supersample), settings
            )
    insp = Inspector(state)
    yield state, insp
    insp.stop()


def settle(insp: Inspector) -> None:
    insp.update()
    wait_until(lambda: insp.update() or insp.current())


def test_pinned_traces_are_the_pixels_the_panes_show(inspected):
    state, insp = inspected
    state.hover = (1, 0.46, 0.31)
    insp.toggle_pin()  # the T key over pane B
    assert insp.pin is not None
    settle(insp)
    entries = insp.entries()
    assert [e.name for e in entries] == ["A", "A'", "B"]
    assert [e.trace.mode for e in entries] == ["scalar", "mip", "gaussian_blending 2x2 fast"]  # as the pane drew it
    for e in entries:
        shown = state.panes[e.slot[0]].parts[e.slot[1]]
        x, y = e.pixel
        assert (e.trace.x, e.trace.y) == (x, y) and not e.stale
        np.testing.assert_allclose(e.trace.color, shown.frame.rgb[y, x], atol=TOL, rtol=0)
        assert abs(e.trace.transmittance - (1 - shown.frame.alpha[y, x])) <= TOL
    # a new frame on pane B: its trace is stale until traced again
    b = state.panes[1].parts["a"]
    b.frame = gb.render(state.scene, b.job.camera, "gaussian_blending", 2)
    assert insp.entries()[2].stale and not insp.current()
    settle(insp)
    assert insp.entries()[2].result.request.frame is b.frame
    # the table's orders: by weight, largest first; blend order without "outside_box" unless all are shown
    t = insp.entries()[2].trace
    steps = t.steps
    by_weight = insp.order(t, True)
    assert [steps[k].weight for k in by_weight] == sorted(
        (s.weight for s in steps if s.rejected != "outside_box"), reverse=True
    )
    assert insp.order(t, False) == [k for k, s in enumerate(steps) if s.rejected != "outside_box"]
    insp.options.show_all = True
    assert insp.order(t, False) == list(range(len(steps)))
    # T again unpins
    insp.toggle_pin()
    assert insp.pin is None and insp.entries()[0].result is None and not insp.current()


def test_export_json_and_csv(inspected, tmp_path):
    state, insp = inspected
    assert insp.export_csv() is None and "no traces" in state.messages[-1][1]
    insp.pin_at(0, 0.5, 0.4)
    settle(insp)
    traces = [(e.name, e.trace) for e in insp.entries()]
    path = insp.export_json()
    assert path.parent == tmp_path and path.suffix == ".json" and str(path) in state.messages[-1][1]
    doc = json.loads(path.read_text())
    assert doc["scene"] == "" and doc["traces"] == [json.loads(t.to_json()) for _, t in traces]
    second = insp.export_json()
    assert second != path and second.exists() and path.exists()  # never overwritten
    path = insp.export_csv()
    assert path.suffix == ".csv" and str(path) in state.messages[-1][1]
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS
    rows = rows[1:]
    assert len(rows) == sum(len(t.steps) for _, t in traces)  # one row per step
    col = {c: k for k, c in enumerate(CSV_COLUMNS)}
    k = 0
    for name, t in traces:
        for s in t.steps:
            row = rows[k]
            k += 1
            assert row[col["pane"]] == name and row[col["mode"]] == t.mode
            assert (int(row[col["x"]]), int(row[col["y"]]), int(row[col["index"]])) == (t.x, t.y, s.index)
            assert float(row[col["weight"]]) == s.weight and float(row[col["T_after"]]) == s.T_after
            assert row[col["rejected"]] == s.rejected
            assert float(row[col["mean_y"]]) == s.mean[1] and float(row[col["color_b"]]) == s.color[2]
            if s.window_size is None:
                assert row[col["window_size_w"]] == "" and row[col["cell"]] == ""
            else:
                assert float(row[col["window_size_w"]]) == s.window_size[0]
