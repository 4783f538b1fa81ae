"""The viewer's render thread, off the UI thread: a `SlotThread` fed per-slot requests (the newest request of a slot
replaces an older one still waiting: stale requests are dropped, and a running render of that slot is cancelled
between tiles, so the thread never finishes a frame nobody will see). A progressive request posts its frame while it
refines: its quick stage (the x1 sample of a supersampled or zoomed-in pane) first, then the full frame's tiles a
few times a second. The thread runs at a lower CPU priority than the UI (Linux), so the window keeps its core.

It holds one renderer per backend for the current scene and asks each backend's `Capabilities`, never its name.
OpenGL: a backend that renders in a GL context does so on one current in the render thread only: its own headless
one (the copy path), or on the GPU display path the context it shares with the window (`display`), where backends
that render into GL textures write the display textures the window draws. A backend that stops working
(BackendFailed) is marked unusable with its reason and requests for it render on what `auto` picks next."""

from __future__ import annotations

import gc
import threading
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable, Hashable

import numpy as np

from ...core.cancel import CancelToken
from ...core.errors import BackendFailed, BackendUnavailable, GBViewerError, RenderCancelled, RenderError
from ...lod import stand_in as sparse_stand_in
from ...model.camera import Camera
from ...model.scene import Scene
from ...render import AUTO, BACKENDS, BackendChoice, Capabilities, Frame, Renderer, RenderSettings, create_gl_context
from ...render.choice import FALLBACK, decide_measured
from ..frames.display import DisplayTextures, SharedContext
from ..frames.refine import companions, render_jobs
from .slots import RENDER_NICE, SlotPolicy, SlotThread


@dataclass(eq=False)
class RenderJob:
    slot: Hashable  # e.g. (pane index, part)
    scene: Scene
    camera: Camera
    settings: RenderSettings
    backend: str = FALLBACK
    info: dict = field(default_factory=dict)  # what the UI needs to show with the result (rate, preview...)
    priority: int = 0  # among waiting requests, higher first (the pane under the cursor)
    preview: bool = False  # a stand-in while the camera moves: a newer preview of the slot waits for it to finish
    # (cancelling each would show none); any other newer request of the slot cancels the running render
    progressive: bool = False  # post the frame while it refines (tiles as they finish)
    underlay: np.ndarray | None = None  # float RGB the refining frame starts from (scaled to the job's size)
    quick: tuple[Camera, RenderSettings] | None = None  # rendered and posted first: a cheap stand-in
    display: str = "copy"  # "gpu": into a display texture (a GpuFrame) where the backend's display path is gpu
    stand_in: bool = False  # a preview of the scene's sparse stand-in (lod.stand_in): its hierarchy is not there yet
    submitted: float = 0.0  # set by the worker: perf_counter at submission
    started: float = 0.0  # set by the render thread: perf_counter when it began the job (0: not yet)


@dataclass(eq=False)
class RenderResult:
    job: RenderJob
    frame: Frame | None
    error: str = ""
    finished: float = 0.0
    cancelled: bool = False  # superseded while it rendered: no frame, nothing to show
    stage: str = "final"  # "quick" (frame is the quick stage), "partial" (partial holds the tiles so far), "final"
    partial: np.ndarray | None = None  # float32 (H, W, 3), still being written by the render
    progress: float = 1.0  # fraction of the frame's tiles done
    failed: bool = False  # the job's backend stopped working (error says why): its slot renders on another next
    started: float = 0.0  # when the render thread began it (perf_counter; 0: not rendered here)


def free(renderer: Renderer) -> None:
    """`renderer.release()`; a renderer that cannot free its buffers (a lost device) must not stop the thread."""
    try:
        renderer.release()
    except Exception:  # noqa: BLE001 - reported, the thread goes on
        traceback.print_exc()


@dataclass(frozen=True)
class RenderPolicy(SlotPolicy):
    """Higher priority first (the pane under the cursor), then the least recently served slot, then submission
    order. A newer preview of a slot waits for its running preview (cancelling each while the camera moves would
    show none); any other newer request of the slot cancels the running render."""

    def rank(self, job: RenderJob, seq: int, served: float) -> tuple:
        return (-job.priority, served, seq)

    def cancels(self, running: RenderJob, newer: RenderJob) -> bool:
        return not (running.preview and newer.preview)


class RenderWorker(SlotThread):
    """One thread rendering the latest request per slot (`RenderPolicy`). `backends`: name -> renderer class (the
    registry's; tests pass their own)."""

    NAME = "gbviewer-render"

    def __init__(
        self,
        shared: SharedContext | None = None,
        on_result: Callable[[], None] | None = None,
        backends: Mapping[str, type[Renderer]] = BACKENDS,
    ) -> None:
        """`on_result`: called from the render thread after each result is posted (the window wakes its event
        loop with it, so a frame or its first tiles are drawn at once)."""
        self._shared = shared
        self._classes = backends
        self._renderers: dict[tuple[str, bool], Renderer] = {}  # this thread's per (backend, stand-in), with `_scene`
        # (or its stand-in) uploaded
        self._gl_ctx = None  # the context this thread's GL-context backends render in
        self._display_ctx = None  # the context shared with the window (GPU display path), current in this thread
        self._last_display = "copy"  # the display of the latest job: free display textures are kept while "gpu"
        self.textures = DisplayTextures()
        self.display: dict[str, tuple[str, str]] = {}  # backend -> ("gpu" | "copy", why), set with `backends`
        self.cancelled = 0  # renders stopped because a newer request of their slot arrived
        self.rendered = 0
        self.backends: dict[str, tuple[bool, str]] = {}  # availability, measured in the render thread
        self.failed: dict[str, str] = {}  # backends that stopped working here, and why
        self.auto: BackendChoice | None = None  # what "auto" renders on, decided from those measures
        self.backends_ready = threading.Event()
        super().__init__(RenderPolicy(), nice=RENDER_NICE, on_result=on_result)

    # ---- UI side -----------------------------------------------------------------------------------------------

    def submit_all(self, jobs: list) -> None:
        for job in jobs:
            job.submitted = time.perf_counter()
        super().submit_all(jobs)

    def backend_status(self, name: str) -> tuple[bool | None, str]:
        """(usable, reason); None while the render thread is still probing. "auto": (True, its choice)."""
        if name == AUTO:
            return (None, "checking...") if self.auto is None else (True, str(self.auto))
        if name not in self._classes:
            return False, "not part of this installation"
        if not self.backends_ready.is_set():
            return None, "checking..."
        return self.backends.get(name, (False, "unknown"))

    def capabilities(self, name: str) -> Capabilities:
        """What backend `name` can do (`Capabilities`)."""
        return self._classes[name].capabilities

    def display_path(self, name: str) -> tuple[str, str]:
        """("gpu" | "copy", why) for frames of backend `name`; copy while the render thread is still probing."""
        if not self.backends_ready.is_set():
            return "copy", "checking..."
        return self.display.get(name, ("copy", "not part of this installation"))

    def return_textures(self) -> None:
        """UI thread, once per frame: hand the display textures of dropped frames back to the render thread."""
        if self.textures.fence_retired():
            self._wake("returns")

    def backend_for(self, name: str) -> str:
        """The backend a request for `name` renders on: `name` (for auto, its choice) where usable, else what auto
        picks (which passes over the backends that stopped working), else the fallback."""
        pick = self.auto.name if self.auto is not None else FALLBACK
        for candidate in (pick if name == AUTO else name, pick):
            if self.backend_status(candidate)[0] is True:
                return candidate
        return FALLBACK

    # ---- render thread -----------------------------------------------------------------------------------------

    def _start(self) -> None:
        if self._shared is not None and self._shared.window is not None:
            try:
                self._display_ctx = self._shared.make_current()
            except Exception as exc:  # noqa: BLE001 - glcontext raises plain Exceptions with the driver's message
                self._shared.why = f"the context shared with the window cannot be used here: {exc}"
        gl_why = self._open_gl_context() if any(c.capabilities.gl_context for c in self._classes.values()) else ""
        for name, cls in self._classes.items():
            try:
                if not cls.capabilities.gl_context:
                    self.backends[name] = tuple(cls.available())  # type: ignore[assignment]
                else:
                    self.backends[name] = cls.check_context(self._gl_ctx) if self._gl_ctx else (False, gl_why)
            except Exception as exc:  # noqa: BLE001 - a backend's probe must not take the viewer down
                self.backends[name] = (False, f"{type(exc).__name__}: {exc}")
        self._decide()
        self.backends_ready.set()

    def _open_gl_context(self) -> str:
        """The context GL-context backends render in: on the GPU display path the one shared with the window (with
        OpenGL 4.3), else a headless one of this thread's own (a context is current in one thread only: a
        process-wide one may be current in another thread, the window's is the UI thread's); why not, if none."""
        if self._display_ctx is not None:
            self._gl_ctx = self._display_ctx
            return ""
        try:
            self._gl_ctx = create_gl_context()
        except BackendUnavailable as exc:
            return str(exc)
        return ""

    def _decide(self) -> None:
        """auto's pick and every backend's display path from what was measured (and what failed since)."""
        self.auto = decide_measured(self.backends, self._gl_ctx, self.failed)
        self.display = {name: self._display_status(name) for name in self._classes}

    def _display_status(self, name: str) -> tuple[str, str]:
        """Whether backend `name`'s frames take the GPU display path (see `display`), and why (not)."""
        cls = self._classes[name]
        if not self.backends.get(name, (False,))[0]:
            return "copy", "backend unavailable"
        if not cls.capabilities.gl_texture:
            return "copy", f"the {name} backend renders into host memory"
        if self._display_ctx is None:
            return "copy", self._shared.why if self._shared is not None else "no window"
        if cls.capabilities.gl_context:
            return "gpu", "rendered into a texture of a context shared with the window"
        try:
            ok, why = cls.gl_interop()  # with the shared context current in this thread
        except Exception as exc:  # noqa: BLE001 - as a backend's probe
            ok, why = False, f"{type(exc).__name__}: {exc}"
        return ("gpu", f"written into the window's texture through {name}-GL interop") if ok else ("copy", why)

    def _renderer_of(self, name: str, stand_in: bool = False) -> Renderer:
        """This thread's renderer of backend `name` with the current scene (or its sparse stand-in: a renderer of
        its own, so that neither is uploaded again for the other) uploaded (made on first use)."""
        if (name, stand_in) not in self._renderers:
            if name not in self._classes:
                raise RenderError(f"unknown backend {name!r}; expected one of {', '.join(self._classes)}")
            ok, why = self.backends.get(name, (False, "not checked"))
            if not ok:
                raise (BackendFailed if name in self.failed else BackendUnavailable)(why)
            cls = self._classes[name]
            renderer = cls(ctx=self._gl_ctx) if cls.capabilities.gl_context else cls()
            renderer.upload(sparse_stand_in(self._scene) if stand_in else self._scene)
            self._renderers[(name, stand_in)] = renderer
        return self._renderers[(name, stand_in)]

    def _release(self) -> None:
        """Free every renderer (and with them the scene and its GPU buffers), in this thread."""
        for renderer in self._renderers.values():
            free(renderer)
        self._renderers.clear()
        super()._release()
        gc.collect()

    def _failed(self, name: str, exc: BackendFailed) -> None:
        """Backend `name` stopped working: unusable from now on (with its renderer's reason), auto picks again."""
        renderers = [self._renderers.pop(key) for key in [k for k in self._renderers if k[0] == name]]
        ok, why = next((r.usable() for r in renderers), (True, ""))
        self.failed[name] = str(exc) if ok else why
        self.backends[name] = (False, f"stopped working: {self.failed[name]}")
        for renderer in renderers:
            free(renderer)
        self._decide()

    def _post(self, result: RenderResult) -> None:
        """Hand an intermediate result to the UI now; a partial frame replaces the same job's earlier one not yet
        taken."""
        with self._lock:
            if result.stage == "partial":
                self._results = [r for r in self._results if not (r.job is result.job and r.stage == "partial")]
            self._results.append(result)
        if self._on_result is not None:
            self._on_result()

    def _between(self, wakes: set[str], job: RenderJob | None) -> None:
        if job is not None:
            self._last_display = job.display
        if self._display_ctx is not None:
            self.textures.recycle(keep=self._last_display == "gpu")

    def _finish(self) -> None:
        self._release()
        if self._display_ctx is not None:
            self.textures.release_all()
        for ctx in {id(c): c for c in (self._gl_ctx, self._display_ctx) if c is not None}.values():
            ctx.release()
        self._gl_ctx = self._display_ctx = None
        if self._shared is not None and self._shared.window is not None:
            self._shared.done_current()
        gc.collect()

    def _companions(self, first: RenderJob, waiting: list) -> list:
        return companions(first, waiting)

    def _work(self, job: RenderJob, cancel: CancelToken) -> RenderResult:
        return self._work_all([job], cancel)[0]

    def _work_all(self, jobs: list, cancel: CancelToken) -> list:
        results = self._render(jobs, cancel)
        self.cancelled += sum(r.cancelled for r in results)
        self.rendered += sum(not r.cancelled for r in results)
        return results

    def _render(self, jobs: list, cancel: CancelToken) -> list:
        """A result per job of `jobs` (one, or the panes of one camera: `refine.companions`)."""
        job = jobs[0]
        if job.scene is not self._scene:
            self._release()  # the previous scene's renderers and GPU buffers, freed in this thread
            self._scene = job.scene

        started = time.perf_counter()
        for j in jobs:
            j.started = started

        def each(**kw) -> list:
            return [RenderResult(j, None, finished=time.perf_counter(), started=started, **kw) for j in jobs]

        try:
            renderer = self._renderer_of(job.backend, job.stand_in)
            if len(jobs) == 1 and job.display == "gpu" and self.display_path(job.backend)[0] == "gpu":
                frames = [self._render_to_texture(renderer, job, cancel)]
            elif len(jobs) == 1 and not job.progressive:
                frames = [renderer.render(job.camera, job.settings, cancel=cancel)]
            else:
                frames = render_jobs(renderer, jobs, cancel, self._post_stage)
            return [RenderResult(j, f, "", time.perf_counter(), started=started) for j, f in zip(jobs, frames)]
        except RenderCancelled:
            return each(cancelled=True)
        except BackendFailed as exc:
            if job.backend not in self.failed:
                self._failed(job.backend, exc)
            return each(error=self.backends[job.backend][1], failed=True)
        except GBViewerError as exc:
            return each(error=str(exc))
        except Exception as exc:  # noqa: BLE001 - shown in the window, never kills the thread
            traceback.print_exc()
            return each(error=f"{type(exc).__name__}: {exc}")

    def _post_stage(
        self, job: RenderJob, stage: str, frame: Frame | None, partial: np.ndarray | None, progress: float
    ) -> None:
        self._post(RenderResult(job, frame, "", time.perf_counter(), stage=stage, partial=partial, progress=progress))

    def _render_to_texture(self, renderer, job: RenderJob, cancel: CancelToken) -> Frame:
        """A GPU display path job: the frame stays in a display texture (a GpuFrame)."""
        tex = self.textures.acquire(self._display_ctx, job.camera.width, job.camera.height)
        self.textures.on_delete = renderer.release_texture  # what the renderer keeps for a texture goes first
        try:
            stats = renderer.render_to_texture(tex, job.camera, job.settings, cancel=cancel)
        except BaseException:
            self.textures.discard(tex)
            raise
        return self.textures.frame(tex, stats)
