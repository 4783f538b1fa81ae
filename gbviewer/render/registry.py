"""The backends by name, imported on first use, and the process's shared renderers (`get_renderer`, `render`).
`backend="auto"` is the backend `choice.choose_backend()` picks for this machine."""

from __future__ import annotations

import importlib
import threading
import weakref
from collections.abc import Callable, Iterator, Mapping

import numpy as np

from ..camera import Camera
from ..errors import RenderError
from ..scene import Scene
from .choice import AUTO, choose_backend
from .types import Frame, Mode, Renderer, RenderSettings

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


_renderers: dict[str, tuple[Renderer, "weakref.ref[Scene]"]] = {}
_renderers_lock = threading.Lock()


def get_renderer(scene: Scene, backend: str = "cpu") -> Renderer:
    """The process's renderer of `backend` ("auto": the best here) with `scene` uploaded. One renderer per backend,
    uploading only when the scene changes: it keeps the last scene alive, never every scene it has seen. One that
    stopped working (`usable()` False) is replaced by a new one."""
    backend = resolve_backend(backend)
    with _renderers_lock:
        entry = _renderers.get(backend)
        if entry is not None and not entry[0].usable()[0]:
            entry = None
        renderer = entry[0] if entry is not None else BACKENDS[backend]()
        if entry is None or entry[1]() is not scene:
            renderer.upload(scene)
            _renderers[backend] = (renderer, weakref.ref(scene))
        return renderer


def render(
    scene: Scene,
    camera: Camera,
    mode: str | Mode = "scalar",
    supersample: int = 1,
    backend: str = "cpu",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    sh_degree: int = 3,
    debug: str = "none",
    cancel: threading.Event | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    partial: np.ndarray | None = None,
    **options,
) -> Frame:
    """Render `scene` from `camera` in `mode` on `backend` (cpu, glsl, cuda, or auto: `choose_backend()`'s pick);
    `options`: depth_correct, et_grade, cell_size, threads.
    `cancel`: a threading.Event; once set, the call raises RenderCancelled within one tile batch. `on_progress`:
    called as fn(done_tiles, total_tiles) from the render. `partial`: a float32 (height, width, 3) array that receives
    each tile's pixels as soon as it is blended (centre out), for showing a frame while it refines."""
    settings = RenderSettings(Mode.parse(mode), supersample, tuple(background), sh_degree, debug, **options)
    return get_renderer(scene, backend).render(camera, settings, cancel=cancel, on_progress=on_progress,
                                                      partial=partial)
