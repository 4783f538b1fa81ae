"""The backends by name, imported on first use, and the process's shared renderers (`get_renderer`, `render`).
`backend="auto"` is the backend `choice.choose_backend()` picks for this machine."""

from __future__ import annotations

import importlib
import threading
import weakref
from collections.abc import Callable, Iterator, Mapping

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import InvalidValue, RenderError
from ..model.camera import Camera
from ..model.scene import Scene
from .choice import AUTO, choose_backend
from .contract import Renderer
from .control import FrameLock
from .types import Frame, Mode, RenderSettings, settings_from

_MODULES = {"cpu": ("cpu", "CpuRenderer"), "cuda": ("cuda", "CudaRenderer"), "glsl": ("glsl", "GlslRenderer")}


class _Backends(Mapping[str, type]):
    """Backend name -> renderer class; a backend's module is imported when its class is first asked for."""

    def __getitem__(self, name: str) -> type:
        if name not in _MODULES:
            raise KeyError(name)
        module, cls = _MODULES[name]
        return getattr(importlib.import_module(f"{__package__}.{module}"), cls)

    def __iter__(self) -> Iterator[str]:
        return iter(_MODULES)

    def __len__(self) -> int:
        return len(_MODULES)


BACKENDS: Mapping[str, type] = _Backends()
BACKEND_NAMES = (AUTO, *_MODULES)  # what `backend=` takes


def capable(flag: str) -> list[str]:
    """The backends whose `capabilities` has `flag` (a field of `Capabilities`, e.g. "trace"), in registry order."""
    return [name for name, cls in BACKENDS.items() if getattr(cls.capabilities, flag)]


def resolve_backend(backend: str) -> str:
    """The backend a request for `backend` runs on: itself, or for "auto" the one `choose_backend()` picks."""
    if backend == AUTO:
        return choose_backend().name
    if backend not in BACKENDS:
        raise RenderError(f"unknown backend {backend!r}; expected one of {', '.join(BACKEND_NAMES)}")
    return backend


def create_renderer(backend: str, **options) -> Renderer:
    """A new renderer of `backend` ("auto": the best here), the caller's own (not shared through `get_renderer`).
    options: the backend's, e.g. `ctx` for glsl: render in that OpenGL context (the app's render thread passes its
    own)."""
    return BACKENDS[resolve_backend(backend)](**options)


def create_gl_context():
    """A new headless OpenGL context for glsl renderers of the calling thread (`create_renderer("glsl", ctx=...)`);
    raises BackendUnavailable with the reason."""
    from .glsl.context import create_context

    return create_context()


class _Slot:
    """The process's renderer of one backend, the lock its frames run under and the scene uploaded to it."""

    def __init__(self, renderer: Renderer) -> None:
        self.renderer, self.lock = renderer, FrameLock()
        self.uploaded: weakref.ref[Scene] | None = None
        self.bound: SharedRenderer | None = None  # the last one handed out (keeps its scene alive)

    def bind(self, scene: Scene) -> None:
        """Upload `scene` unless it is the one uploaded. Called with the lock held."""
        if self.uploaded is None or self.uploaded() is not scene:
            self.uploaded = None
            self.renderer.upload(scene)
            self.uploaded = weakref.ref(scene)


class SharedRenderer:
    """The process's renderer of a backend, bound to one scene: what `get_renderer` returns. Its frames (render,
    render_many, render_to_texture, trace) and uploads run under the backend's lock with its own scene uploaded
    first, so threads that render different scenes through `get_renderer` or `render` each get their own scene's
    frames (one frame at a time per backend). Everything else is the renderer's (name, available, release_texture,
    ...)."""

    _SCENE_CALLS = frozenset({"render", "render_many", "render_to_texture", "trace"})

    def __init__(self, slot: _Slot, scene: Scene) -> None:
        self._slot, self._scene = slot, scene

    def __getattr__(self, name: str):
        attr = getattr(self._slot.renderer, name)
        if name not in self._SCENE_CALLS:
            return attr

        def call(*args, **kwargs):
            if name == "render_many":
                jobs = args[0] if args else kwargs.get("jobs", ())
                for job in jobs if isinstance(jobs, (list, tuple)) else [jobs]:
                    _check_job(name, *job if isinstance(job, tuple) and len(job) == 2 else (job, None))
            else:  # render_to_texture(texture, camera, settings), the others (camera, settings, ...)
                first = 1 if name == "render_to_texture" else 0
                _check_job(name, *[*args[first:], kwargs.get("camera"), kwargs.get("settings")][:2])
            with self._slot.lock:
                self._slot.bind(self._scene)
                return attr(*args, **kwargs)

        return call

    def upload(self, scene: Scene) -> None:
        """Bind this handle to `scene` (uploaded now, and again before a frame wherever another scene came since)."""
        with self._slot.lock:
            self._scene = scene
            self._slot.bind(scene)

    def release(self) -> None:
        """Free the shared renderer's scene and buffers; the next frame of any handle uploads its scene again."""
        with self._slot.lock:
            self._slot.uploaded = None
            self._slot.renderer.release()


def _check_job(call: str, camera: object, settings: object) -> None:
    """A frame's camera and settings as a renderer takes them, else one line naming the call."""
    if not (isinstance(camera, Camera) and isinstance(settings, RenderSettings)):
        raise InvalidValue(
            f"{call}: expected a gbviewer.Camera and a RenderSettings (RenderSettings.parse(spec)) "
            f"per frame, got {type(camera).__name__} and {type(settings).__name__}"
        )


_renderers: dict[str, _Slot] = {}
_renderers_lock = threading.Lock()


def get_renderer(scene: Scene, backend: str = "cpu") -> SharedRenderer:
    """The process's renderer of `backend` ("auto": the best here) bound to `scene` (see SharedRenderer: safe to use
    from any thread). One renderer per backend, uploading only when the scene changes: it keeps the last scene
    alive, never every scene it has seen. One that stopped working (`usable()` False) is replaced by a new one."""
    if not isinstance(scene, Scene):
        raise InvalidValue(
            f"get_renderer: the first argument is the scene (a gbviewer.Scene: gb.load(path)), "
            f"got {type(scene).__name__} {scene!r:.60}"
        )
    backend = resolve_backend(backend)
    with _renderers_lock:
        slot = _renderers.get(backend)
        if slot is None or not slot.renderer.usable()[0]:
            slot = _renderers[backend] = _Slot(BACKENDS[backend]())
    with slot.lock:
        slot.bind(scene)
        if slot.bound is None or slot.bound._scene is not scene:
            slot.bound = SharedRenderer(slot, scene)
        return slot.bound


def render(
    scene: Scene,
    camera: Camera,
    mode: str | Mode | RenderSettings = "scalar",
    supersample: int | None = None,
    backend: str = "cpu",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    sh_degree: int | None = None,
    debug: str = "none",
    cancel: Cancellable | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    partial: np.ndarray | None = None,
    **options,
) -> Frame:
    """Render `scene` from `camera` in `mode` (a RenderSettings, which says everything; or any spec
    `RenderSettings.parse` takes, `supersample`, `sh_degree` and `options` filling what it leaves unset and agreeing
    with what it sets) on `backend` (cpu, glsl, cuda, or auto: `choose_backend()`'s pick); `options`: depth_correct,
    et_grade, cell_size, threads, lod, seed and frame (stochastic).
    `cancel`: a gbviewer.CancelToken (or a threading.Event); once set, the call raises RenderCancelled within one
    tile batch. `on_progress`: called as fn(done_tiles, total_tiles) from the rendering thread (an exception it raises
    cancels the render: CallbackError, chained to it). `partial`: a float32 (height, width, 3) array that receives
    each tile's pixels as soon as it is blended (centre out), for showing a frame while it refines. Safe from any
    thread, with any scenes (each call renders its own scene)."""
    settings = settings_from(mode, "render", background, debug, supersample=supersample, sh_degree=sh_degree, **options)
    return get_renderer(scene, backend).render(
        camera, settings, cancel=cancel, on_progress=on_progress, partial=partial
    )
