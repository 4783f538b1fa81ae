"""Rendering: the types every backend shares (`types`), the per-frame preparation (`prepare`), the backends
(`cpu`, `cuda`, `glsl/`), the registry that creates them by name (`get_renderer`, `render`) and the choice of the
best one here (`choice`: `backend="auto"`)."""

from .choice import AUTO, BackendChoice, choose_backend
from .cpu import CpuRenderer
from .cuda import CudaRenderer
from .registry import BACKEND_NAMES, BACKENDS, create_gl_context, create_renderer, get_renderer, render, resolve_backend
from .types import SORT_ENTRY_BYTES, Frame, FrameStats, Mode, Renderer, RenderSettings

__all__ = [
    "AUTO", "BACKENDS", "BACKEND_NAMES", "SORT_ENTRY_BYTES", "BackendChoice", "CpuRenderer", "CudaRenderer", "Frame",
    "FrameStats", "Mode", "RenderSettings", "Renderer", "choose_backend", "create_gl_context", "create_renderer",
    "get_renderer", "render", "resolve_backend",
]
