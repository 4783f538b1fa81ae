"""The pixel inspector's state and its thread (no imgui; `view` draws it).

A pin is one pane-relative position (u, v), the same in every visible pane. Each visible pane part maps it to the
pixel of its final frame drawn there (`render_pixel`: at x1/8 one render pixel covers 8x8 display pixels) and has
that pixel traced by `TraceThread` (the CPU kernel's `PixelTrace`, as `gb.trace_pixel` makes it) with the camera
and settings of the frame it shows, so the traced colour is the pixel on screen. Traces take 0.05-0.5 s: they run
off the UI thread, the newest request per pane part wins, and a pane whose frame changes is traced again.
"""

from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Hashable

import numpy as np

from ...core.cancel import CancelToken
from ...core.errors import GBViewerError
from ...model.camera import Camera
from ...model.scene import Scene
from ...outputs.trace_report import write_traces, write_traces_csv
from ...render import Frame, PixelTrace, RenderSettings, capable
from ...render.choice import FALLBACK
from ..difference.views import is_final
from ..screenshots import shot_name
from ..settings import PANE_NAMES
from ..state import AppState
from ..threads.slots import SlotPolicy, SlotThread
from ..ui.layout import Rect

Slot = tuple[int, str]  # (pane index, part)
EDGE_EPS = 1e-6  # of a render pixel: rounding below a pixel edge (render_pixel)
MARGIN, MARGIN_MIN, MARGIN_MAX = 1.5, 0.25, 64.0  # output pixels drawn around the pinned one


def render_pixel(u: float, v: float, width: int, height: int) -> tuple[int, int]:
    """The pixel of a width x height render drawn at pane-relative (u, v) (the render covers the pane, nearest).
    Zoomed in by an even factor a display pixel's centre lies on a pixel edge: it takes the pixel right of (below)
    it, as exact arithmetic and `figure.upscale_nearest` do (u * width may round to just below the edge)."""

    def cell(t: float, n: int) -> int:
        return min(n - 1, max(0, math.floor(t * n + EDGE_EPS)))

    return cell(u, width), cell(v, height)


def snap(u: float, n: int) -> float:
    """`u` moved to the centre of the one of n equal cells it falls in (a display pixel of a pane n pixels wide)."""
    return (min(n - 1, max(0, math.floor(u * n))) + 0.5) / n


def remap(pin: tuple[float, float], old: Camera, new: Camera) -> tuple[float, float]:
    """Pane-relative `pin` on `old`'s image moved to where the same point of the image plane (the same scene point,
    for the same pose) lies on `new`'s image: the panes changed shape, not the view."""
    x, y = (pin[0] * old.width - old.cx) / old.fx, (pin[1] * old.height - old.cy) / old.fy
    return (x * new.fx + new.cx) / new.width, (y * new.fy + new.cy) / new.height


def same_pose(a: Camera, b: Camera) -> bool:
    return a.projection == b.projection and np.array_equal(a.R, b.R) and np.array_equal(a.t, b.t)


def pixel_box(rect: Rect, x: int, y: int, width: int, height: int) -> tuple[float, float, float, float]:
    """Where pixel (x, y) of a width x height render is drawn in a pane at `rect`: (x0, y0, x1, y1)."""
    sx, sy = rect.w / width, rect.h / height
    return rect.x + x * sx, rect.y + y * sy, rect.x + (x + 1) * sx, rect.y + (y + 1) * sy


def ellipse_points(
    mean: tuple[float, float], covariance: tuple[float, float, float], radius: float, n: int = 48
) -> np.ndarray | None:
    """n points (n, 2) on the ellipse of Mahalanobis `radius` of a 2D Gaussian (covariance xx, xy, yy); None when it
    is degenerate or not finite."""
    xx, xy, yy = covariance
    c = np.array([[xx, xy], [xy, yy]], np.float64)
    if not (np.isfinite(c).all() and np.isfinite(mean).all() and math.isfinite(radius)):
        return None
    lam, vec = np.linalg.eigh(c)
    if lam[0] <= 0:
        return None
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], 1) * (radius * np.sqrt(lam))
    return np.asarray(mean, np.float64) + circle @ vec.T


# ---- the thread ----------------------------------------------------------------------------------------------------


@dataclass(eq=False)
class TraceRequest:
    slot: Hashable
    scene: Scene
    frame: Frame  # the frame on the pane: its pixel (x, y) is traced
    camera: Camera
    settings: RenderSettings
    x: int
    y: int
    backend: str = FALLBACK  # the frame's (the trace is the tracing backend's: `TraceThread.backend`)


@dataclass
class TraceResult:
    request: TraceRequest
    trace: PixelTrace | None
    error: str = ""
    seconds: float = 0.0


class TraceThread(SlotThread):
    """One thread tracing the newest request per slot, the longest-waiting slot first (a running trace finishes: it
    is not cancellable); `trace` computes one (by default the thread's own renderer's `trace`, of the first backend
    whose capabilities include tracing: `backend`)."""

    NAME = "gbviewer-trace"

    def __init__(self, trace: Callable[[TraceRequest], PixelTrace] | None = None) -> None:
        self._trace = trace or self._trace_own
        self.backend = capable("trace")[0]
        super().__init__(SlotPolicy(cancel_running=False), backend=self.backend)

    def _work(self, req: TraceRequest, cancel: CancelToken) -> TraceResult:
        t0 = time.perf_counter()
        try:
            result = TraceResult(req, self._trace(req))
        except GBViewerError as exc:
            result = TraceResult(req, None, str(exc))
        except Exception as exc:  # noqa: BLE001 - shown in the inspector, never kills the thread
            traceback.print_exc()
            result = TraceResult(req, None, f"{type(exc).__name__}: {exc}")
        result.seconds = time.perf_counter() - t0
        return result

    def _trace_own(self, req: TraceRequest) -> PixelTrace:
        return self._renderer_for(req.scene).trace(req.camera, req.settings, req.x, req.y)


# ---- the UI side ---------------------------------------------------------------------------------------------------


@dataclass
class InspectorOptions:
    show_all: bool = False  # every list entry in the table and the slider (else: the table without the "outside_box"
    #                         ones, the slider only the steps that added to the pixel)
    by_weight: bool = True  # the table's order: largest weight first (else blend order)
    alone: Slot | None = None  # the pane part drawn alone (None: side by side)
    margin: float = MARGIN  # output pixels drawn around the pinned one (the mouse wheel zooms)
    step: dict[Slot, int] = field(default_factory=dict)  # per pane part: the step the slider is on (into .steps)


@dataclass
class Entry:
    """One visible pane part in the inspector: its name, the pixel under the pin in the frame it shows (None
    without a final frame), its latest trace and whether that is of another frame or pixel."""

    slot: Slot
    name: str
    pixel: tuple[int, int] | None
    result: TraceResult | None
    stale: bool

    @property
    def trace(self) -> PixelTrace | None:
        return self.result.trace if self.result is not None else None


class Inspector:
    """The pin, the traces of the visible pane parts and the actions on them (keys.py: `toggle_pin`)."""

    def __init__(self, state: AppState, thread: TraceThread | None = None) -> None:
        self.state = state
        self.thread = thread or TraceThread()
        self.options = InspectorOptions()
        self.pin: tuple[float, float] | None = None  # pane-relative (u, v)
        self._pinned_on: Camera | None = None  # the camera of pane A the pin is a position on (`follow`)
        self.results: dict[Slot, TraceResult] = {}
        self._asked: dict[Slot, TraceRequest] = {}
        self._scene: Scene | None = None
        self._cache: dict[tuple, Any] = {}  # per trace: its steps, the orders shown

    # ---- actions ------------------------------------------------------------------------------------------------

    def toggle_pin(self) -> None:
        """Unpin; or pin the pixel under the cursor (the panes' centre without one)."""
        if self.pin is not None:
            self.unpin()
        elif self.state.hover is not None:
            self.pin_at(*self.state.hover)
        else:
            self.pin_at(0, 0.5, 0.5)

    def pin_at(self, i: int, u: float, v: float) -> None:
        """Pin pane-relative (u, v) of pane i, moved to the centre of the display pixel there."""
        r, (sx, sy) = self.state.panes[i].rect, self.state.scale
        self.pin = (snap(u, max(1, round(r.w * sx))), snap(v, max(1, round(r.h * sy))))
        self._pinned_on = self.state.pane_camera(0)

    def follow(self) -> None:
        """After each layout: where the panes changed shape under the same view (the docked inspector opened or
        closed, the window resized), the pin moves to keep the same point of the scene (`remap`)."""
        if self.pin is None:
            return
        cam = self.state.pane_camera(0)
        old, self._pinned_on = self._pinned_on, cam
        if (
            old is not None
            and same_pose(old, cam)
            and (old.width, old.height, old.fx, old.fy, old.cx, old.cy)
            != (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
        ):
            self.pin = remap(self.pin, old, cam)

    def zoom(self, wheel: float) -> None:
        """The drawing's margin around the pixel, 1.25x smaller per wheel step up (zoom in), bounded."""
        self.options.margin = min(MARGIN_MAX, max(MARGIN_MIN, self.options.margin * 1.25**-wheel))

    def unpin(self) -> None:
        self.pin = self._pinned_on = None
        self.results.clear()
        self._asked.clear()
        self._cache.clear()
        self.thread.clear()

    def export_json(self, path: str | Path | None = None) -> Path | None:
        """The traces shown as JSON, as `gbviewer trace --json` writes them (panes in order)."""
        return self._export("json", path)

    def export_csv(self, path: str | Path | None = None) -> Path | None:
        """The traces shown as CSV, one row per step with the pane's name and mode."""
        return self._export("csv", path)

    def _export(self, kind: str, path: str | Path | None) -> Path | None:
        s = self.state
        traces = [(e.name, e.trace) for e in self.entries() if e.trace is not None and not e.stale]
        if not traces:
            s.message("no traces to export yet", "warn")
            return None
        path = Path(path) if path else shot_name(s, "trace", f".{kind}")
        scene = str(s.scene_path) if s.scene_path else ""
        try:
            if kind == "json":
                write_traces(path, [t for _, t in traces], scene)
            else:
                write_traces_csv(path, traces)
        except (OSError, GBViewerError) as exc:
            s.message(f"trace export failed: {exc}", "error")
            return None
        s.message(f"saved {path}")
        return path

    # ---- requests and results -----------------------------------------------------------------------------------

    def pixel(self, i: int, part: str = "a") -> tuple[int, int] | None:
        """The pinned pixel in pane i's part's final frame (None unpinned, or without a final frame)."""
        shown = self.state.panes[i].parts[part]
        if self.pin is None or not is_final(shown, self.state.scene):
            return None
        return render_pixel(*self.pin, shown.job.camera.width, shown.job.camera.height)

    def update(self) -> None:
        """Once per UI frame, after the panes took their frames: finished traces in, new requests out."""
        s = self.state
        if s.scene is not self._scene:
            self._scene = s.scene
            self.thread.forget()
            self.results.clear()
            self._asked.clear()
        for res in self.thread.results():
            if self._asked.get(res.request.slot) is res.request:
                self.results[res.request.slot] = res
                self._cache.clear()
        if self.pin is None:
            return
        for p in s.visible:
            for part in s.parts(p.index):
                slot, shown, xy = (p.index, part), p.parts[part], self.pixel(p.index, part)
                asked = self._asked.get(slot)
                if xy is None or (asked is not None and asked.frame is shown.frame and (asked.x, asked.y) == xy):
                    continue
                job = shown.job
                self._asked[slot] = req = TraceRequest(
                    slot, s.scene, shown.frame, job.camera, replace(job.settings, debug="none"), *xy, job.backend
                )
                self.thread.submit(req)

    def entries(self) -> list[Entry]:
        """The visible pane parts, in order."""
        out = []
        for p in self.state.visible:
            for part in self.state.parts(p.index):
                slot, shown, xy = (p.index, part), p.parts[part], self.pixel(p.index, part)
                res = self.results.get(slot)
                stale = res is not None and (
                    res.request.frame is not shown.frame or (res.request.x, res.request.y) != xy
                )
                out.append(Entry(slot, PANE_NAMES[p.index] + ("'" if part == "b" else ""), xy, res, stale))
        return out

    def current(self) -> bool:
        """Whether every visible pane part has the trace of the pinned pixel in the frame it shows."""
        if self.pin is None or self.thread.busy():
            return False
        return all(e.pixel is not None and e.trace is not None and not e.stale for e in self.entries())

    def steps(self, trace: PixelTrace) -> tuple:
        """trace.steps (kept until the traces change: the property builds the tuple on each call)."""
        key = (id(trace), "steps")
        if key not in self._cache:
            self._cache[key] = trace.steps
        return self._cache[key]

    def order(self, trace: PixelTrace, by_weight: bool) -> list[int]:
        """Indices into trace.steps of the steps shown (with `options.show_all` every list entry, else those the
        splat's box let through: not "outside_box"), by weight (largest first) or in blend order (kept until the
        traces change)."""
        key = (id(trace), self.options.show_all, by_weight)
        if key not in self._cache:
            steps = self.steps(trace)
            rows = [k for k, s in enumerate(steps) if self.options.show_all or s.rejected != "outside_box"]
            if by_weight:
                rows.sort(key=lambda k: -steps[k].weight)
            self._cache[key] = rows
        return self._cache[key]

    def slider_steps(self, trace: PixelTrace) -> list[int]:
        """The steps the slider goes through, in blend order: those that added to the pixel (with
        `options.show_all`, every list entry); every shown one where none added."""
        blend = self.order(trace, by_weight=False)
        steps = self.steps(trace)
        added = [k for k in blend if self.options.show_all or not steps[k].rejected]
        return added or blend

    def ellipse(self, trace: PixelTrace, k: int) -> np.ndarray | None:
        """Step k's splat at its cut-off (`ellipse_points`, output pixels; kept until the traces change)."""
        key = (id(trace), "ellipse", k)
        if key not in self._cache:
            s = self.steps(trace)[k]
            self._cache[key] = ellipse_points(s.mean, s.covariance, s.cutoff)
        return self._cache[key]

    def stop(self) -> None:
        self.thread.stop()
