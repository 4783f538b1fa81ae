"""The viewer's render thread, off the UI thread: fed per-slot requests (the newest request of a slot replaces an
older one still waiting: stale requests are dropped, and a running render of that slot is cancelled between tiles,
so the thread never finishes a frame nobody will see). A progressive request posts its frame while it refines: its
quick stage (the x1 sample of a supersampled or zoomed-in pane) first, then the full frame's tiles a few times a
second. The thread runs at a lower CPU priority than the UI (Linux), so the window keeps its core. OpenGL: the
'glsl' backend renders on a context current in the render thread only: its own headless one (the copy path), or on
the GPU display path the context it shares with the window (`display`), where GPU backends render into display
textures the window draws."""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

import numpy as np

from ..camera import Camera
from ..errors import BackendUnavailable, GBViewerError, RenderCancelled
from ..render import (AUTO, BACKENDS, BackendChoice, Frame, RenderSettings, create_gl_context, create_renderer,
                      get_renderer)
from ..render.choice import GlProbe, decide
from ..scene import Scene
from .display import DisplayTextures, SharedContext


RENDER_NICE = 10  # added to the render thread's (and its OpenMP threads') niceness: the UI gets a core when it asks
PARTIAL_INTERVAL_S = 0.1  # how often a refining frame is posted (the first finished tiles at once)


@dataclass
class RenderJob:
    slot: Hashable  # e.g. (pane index, part)
    scene: Scene
    camera: Camera
    settings: RenderSettings
    backend: str = "cpu"
    info: dict = field(default_factory=dict)  # what the UI needs to show with the result (rate, preview...)
    seq: int = 0  # set by the worker: submission order
    priority: int = 0  # among waiting requests, higher first (the pane under the cursor)
    preview: bool = False  # a stand-in while the camera moves: a newer preview of the slot waits for it to finish
    # (cancelling each would show none); any other newer request of the slot cancels the running render
    progressive: bool = False  # post the frame while it refines (tiles as they finish)
    underlay: np.ndarray | None = None  # float RGB the refining frame starts from (scaled to the job's size)
    quick: tuple[Camera, RenderSettings] | None = None  # rendered and posted first: a cheap stand-in
    display: str = "copy"  # "gpu": into a display texture (a GpuFrame) where the backend's display path is gpu
    submitted: float = 0.0  # set by the worker: perf_counter at submission


@dataclass
class RenderResult:
    job: RenderJob
    frame: Frame | None
    error: str = ""
    finished: float = 0.0
    cancelled: bool = False  # superseded while it rendered: no frame, nothing to show
    stage: str = "final"  # "quick" (frame is the quick stage), "partial" (partial holds the tiles so far), "final"
    partial: np.ndarray | None = None  # float32 (H, W, 3), still being written by the render
    progress: float = 1.0  # fraction of the frame's tiles done


def lower_priority(amount: int = RENDER_NICE) -> None:
    """Raise the calling thread's niceness by `amount` (Linux, where a thread is a task; elsewhere it would renice
    the whole process, so nothing): the threads it starts later, OpenMP's and Mesa's included, inherit it. For the
    threads that render or load beside the window."""
    if not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + amount))
    except OSError:
        pass


def scaled_nearest(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """`image` (H, W, 3) resized to (height, width, 3) float32 by nearest neighbour."""
    h, w = image.shape[:2]
    ys = np.arange(height) * h // height
    xs = np.arange(width) * w // width
    return np.ascontiguousarray(image[ys[:, None], xs[None, :], :3], np.float32)


class RenderWorker:
    """One thread rendering the latest request per slot, least recently served slot first."""

    def __init__(self, shared: SharedContext | None = None, on_result: Callable[[], None] | None = None) -> None:
        """`on_result`: called from the render thread after each result is posted (the window wakes its event
        loop with it, so a frame or its first tiles are drawn at once)."""
        self._shared = shared
        self._on_result = on_result
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._pending: dict[Hashable, RenderJob] = {}
        self._running: RenderJob | None = None
        self._cancel_running = threading.Event()  # set when the running job's slot gets a newer request
        self._results: list[RenderResult] = []
        self._served: dict[Hashable, float] = {}
        self._seq = 0
        self._stop = False
        self._scene: Scene | None = None  # the scene whose renderers the thread holds (freed in this thread)
        self._gl_ctx = None  # this thread's headless context for the glsl backend
        self._glsl: tuple[Scene, Any] | None = None
        self._display_ctx = None  # the context shared with the window (GPU display path), current in this thread
        self._last_display = "copy"  # the display of the latest job: free display textures are kept while "gpu"
        self._returns = False  # the UI handed display textures back
        self.textures = DisplayTextures()
        self.display: dict[str, tuple[str, str]] = {}  # backend -> ("gpu" | "copy", why), set with `backends`
        self.dropped = 0  # requests replaced before they started
        self.cancelled = 0  # renders stopped because a newer request of their slot arrived
        self.rendered = 0
        self.backends: dict[str, tuple[bool, str]] = {}  # availability, measured in the render thread
        self.auto: BackendChoice | None = None  # what "auto" renders on, decided from those measures
        self.backends_ready = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="gbviewer-render", daemon=True)
        self._thread.start()

    # ---- UI side -----------------------------------------------------------------------------------------------

    def submit(self, job: RenderJob) -> None:
        with self._lock:
            self._seq += 1
            job.seq = self._seq
            job.submitted = time.perf_counter()
            if job.slot in self._pending:
                self.dropped += 1
            running = self._running
            if running is not None and running.slot == job.slot and not (running.preview and job.preview):
                self._cancel_running.set()
            self._pending[job.slot] = job
            self._wake.notify()

    def cancel(self, slot: Hashable) -> None:
        """Forget `slot`'s waiting request and stop its running render."""
        with self._lock:
            self._pending.pop(slot, None)
            if self._running is not None and self._running.slot == slot:
                self._cancel_running.set()

    def results(self) -> list[RenderResult]:
        with self._lock:
            out, self._results = self._results, []
        return out

    def busy(self, slot: Hashable | None = None) -> bool:
        """Whether `slot` (or any slot) has a request waiting or rendering."""
        with self._lock:
            if slot is None:
                return bool(self._pending) or self._running is not None
            return slot in self._pending or (self._running is not None and self._running.slot == slot)

    def backend_status(self, name: str) -> tuple[bool | None, str]:
        """(usable, reason); None while the render thread is still probing. "auto": (True, its choice)."""
        if name == AUTO:
            return (None, "checking...") if self.auto is None else (True, str(self.auto))
        if name not in BACKENDS:
            return False, "not part of this installation"
        if not self.backends_ready.is_set():
            return None, "checking..."
        return self.backends.get(name, (False, "unknown"))

    def display_path(self, name: str) -> tuple[str, str]:
        """("gpu" | "copy", why) for frames of backend `name`; copy while the render thread is still probing."""
        if not self.backends_ready.is_set():
            return "copy", "checking..."
        return self.display.get(name, ("copy", "not part of this installation"))

    def return_textures(self) -> None:
        """UI thread, once per frame: hand the display textures of dropped frames back to the render thread."""
        if self.textures.fence_retired():
            with self._lock:
                self._returns = True
                self._wake.notify()

    def backend_for(self, name: str) -> str:
        """The backend a request for `name` renders on: `name` (for auto, its choice) where usable, else cpu."""
        if name == AUTO:
            name = self.auto.name if self.auto is not None else "cpu"
        return name if self.backend_status(name)[0] is True else "cpu"

    def stop(self, timeout: float = 30.0) -> None:
        with self._lock:
            self._stop = True
            self._pending.clear()
            self._cancel_running.set()
            self._wake.notify()
        self._thread.join(timeout)

    # ---- render thread -----------------------------------------------------------------------------------------

    def _check_backends(self) -> None:
        if self._shared is not None and self._shared.window is not None:
            try:
                self._display_ctx = self._shared.make_current()
            except Exception as exc:  # noqa: BLE001 - glcontext raises plain Exceptions with the driver's message
                self._shared.why = f"the context shared with the window cannot be used here: {exc}"
        for name, cls in BACKENDS.items():
            try:
                if name == "glsl":
                    self.backends[name] = self._glsl_context_status()
                else:
                    self.backends[name] = tuple(cls.available())  # type: ignore[assignment]
            except Exception as exc:  # noqa: BLE001 - a backend's probe must not take the viewer down
                self.backends[name] = (False, f"{type(exc).__name__}: {exc}")
        cuda = self.backends.get("cuda", (False, "not part of this installation"))
        self.auto = decide(cuda, GlProbe.of(self._gl_ctx, self.backends.get("glsl", (False, ""))[1]))
        self.display = {name: self._display_status(name) for name in BACKENDS}
        self.backends_ready.set()

    def _display_status(self, name: str) -> tuple[str, str]:
        """Whether backend `name`'s frames take the GPU display path (see `display`), and why (not)."""
        if not self.backends.get(name, (False,))[0]:
            return "copy", "backend unavailable"
        if name == "cpu":
            return "copy", "the cpu backend renders into host memory"
        if self._display_ctx is None:
            return "copy", self._shared.why if self._shared is not None else "no window"
        if name == "glsl":
            return "gpu", "rendered into a texture of a context shared with the window"
        try:
            ok, why = BACKENDS[name].gl_interop()  # cuda, with the shared context current in this thread
        except Exception as exc:  # noqa: BLE001 - as a backend's probe
            ok, why = False, f"{type(exc).__name__}: {exc}"
        return ("gpu", "written into the window's texture through CUDA-GL interop") if ok else ("copy", why)

    def _glsl_context_status(self) -> tuple[bool, str]:
        """The glsl backend runs in this thread on a headless context of its own (an OpenGL context is current in
        one thread only: the glsl backend's process-wide one may be current in another thread, and the window's
        is the UI thread's); on the GPU display path, on the context shared with the window (OpenGL 4.3)."""
        if self._display_ctx is not None:
            self._gl_ctx = self._display_ctx
            return BACKENDS["glsl"].check_context(self._gl_ctx)
        try:
            self._gl_ctx = create_gl_context()
        except BackendUnavailable as exc:
            return False, str(exc)
        return BACKENDS["glsl"].check_context(self._gl_ctx)

    def _renderer(self, scene: Scene, backend: str):
        if backend != "glsl" or "glsl" not in BACKENDS:
            return get_renderer(scene, backend)
        ok, why = self.backends.get("glsl", (False, "not checked"))
        if not ok:
            raise BackendUnavailable(why)
        if self._glsl is None or self._glsl[0] is not scene:
            self._release_glsl()
            renderer = create_renderer("glsl", ctx=self._gl_ctx)
            renderer.upload(scene)
            self._glsl = (scene, renderer)
        return self._glsl[1]

    def _release_glsl(self) -> None:
        if self._glsl is not None:
            self._glsl[1].release()
            self._glsl = None

    def _post(self, result: RenderResult) -> None:
        """Hand a result to the UI; a partial frame replaces the same job's earlier one not yet taken."""
        with self._lock:
            if result.stage == "partial":
                self._results = [r for r in self._results if not (r.job is result.job and r.stage == "partial")]
            self._results.append(result)
        if self._on_result is not None:
            self._on_result()

    def _loop(self) -> None:
        lower_priority()
        self._check_backends()
        while True:
            with self._lock:
                while not self._pending and not self._stop and not self._returns:
                    self._wake.wait()
                if self._stop:
                    break
                self._returns = False
                job = None
                if self._pending:
                    slot = min(self._pending, key=lambda s: (-self._pending[s].priority, self._served.get(s, 0.0),
                                                              self._pending[s].seq))
                    job = self._pending.pop(slot)
                    self._running = job
                    self._cancel_running = threading.Event()
            if job is not None:
                self._last_display = job.display
            if self._display_ctx is not None:
                self.textures.recycle(keep=self._last_display == "gpu")
            if job is None:
                continue
            result = self._render(job, self._cancel_running)
            self._post(result)
            with self._lock:
                self._running = None
                self._served[slot] = time.perf_counter()
                self.cancelled += result.cancelled
                self.rendered += not result.cancelled
        self._scene = None
        self._release_glsl()
        if self._display_ctx is not None:
            self.textures.release_all()
        for ctx in {id(c): c for c in (self._gl_ctx, self._display_ctx) if c is not None}.values():
            ctx.release()
        self._gl_ctx = self._display_ctx = None
        if self._shared is not None and self._shared.window is not None:
            self._shared.done_current()
        gc.collect()

    def _render(self, job: RenderJob, cancel: threading.Event) -> RenderResult:
        if job.scene is not self._scene:
            self._scene = job.scene
            if self._glsl is not None and self._glsl[0] is not job.scene:
                self._release_glsl()  # else it would keep the previous scene and its GPU buffers while cpu renders
            gc.collect()  # free the previous scene's renderers (and GL buffers) in this thread
        try:
            renderer = self._renderer(job.scene, job.backend)
            if job.display == "gpu" and self.display_path(job.backend)[0] == "gpu":
                frame = self._render_to_texture(renderer, job, cancel)
            elif not job.progressive:
                frame = renderer.render(job.camera, job.settings, cancel=cancel)
            else:
                frame = self._refine(renderer, job, cancel)
            return RenderResult(job, frame, "", time.perf_counter())
        except RenderCancelled:
            return RenderResult(job, None, "", time.perf_counter(), cancelled=True)
        except GBViewerError as exc:
            return RenderResult(job, None, str(exc), time.perf_counter())
        except Exception as exc:  # noqa: BLE001 - shown in the window, never kills the thread
            traceback.print_exc()
            return RenderResult(job, None, f"{type(exc).__name__}: {exc}", time.perf_counter())

    def _render_to_texture(self, renderer, job: RenderJob, cancel: threading.Event) -> Frame:
        """A GPU display path job: the frame stays in a display texture (a GpuFrame)."""
        tex = self.textures.acquire(self._display_ctx, job.camera.width, job.camera.height)
        if hasattr(renderer, "release_texture"):  # cuda: its registration of a texture goes before the texture
            self.textures.on_delete = renderer.release_texture
        try:
            stats = renderer.render_to_texture(tex, job.camera, job.settings, cancel=cancel)
        except BaseException:
            self.textures.discard(tex)
            raise
        return self.textures.frame(tex, stats)

    def _refine(self, renderer, job: RenderJob, cancel: threading.Event) -> Frame:
        """A progressive job: the quick stage, then the frame with its finished tiles posted as they come."""
        base = job.underlay
        if job.quick is not None:
            quick = renderer.render(*job.quick, cancel=cancel)
            self._post(RenderResult(job, quick, "", time.perf_counter(), stage="quick"))
            base = quick.rgb
        w, h = job.camera.width, job.camera.height
        partial = scaled_nearest(base, w, h) if base is not None else np.zeros((h, w, 3), np.float32)
        posted = [0.0, 0]  # when, tiles done

        def on_progress(done: int, total: int) -> None:
            now = time.perf_counter()
            if done > posted[1] and done < total and (posted[1] == 0 or now - posted[0] >= PARTIAL_INTERVAL_S):
                posted[:] = [now, done]
                self._post(RenderResult(job, None, "", now, stage="partial", partial=partial, progress=done / total))

        return renderer.render(job.camera, job.settings, cancel=cancel, on_progress=on_progress, partial=partial)
