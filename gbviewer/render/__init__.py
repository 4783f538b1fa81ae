"""Rendering: the types every backend shares (`types`), the contract each subclasses (`contract`), the per-frame
preparation (`prepare`), the backends (`cpu`, `cuda`, `glsl/`), the registry that creates them by name
(`get_renderer`, `render`), the choice of the best one here (`choice`: `backend="auto"`), the pixel trace of the CPU
kernel (`trace`) and how the native modules were built (`build_info`)."""

from .build_info import build_info, compiler_line, simd_line
from .choice import AUTO, BackendChoice, choose_backend
from .contract import Capabilities, Renderer
from .cpu import CpuRenderer
from .cuda import CudaRenderer
from .registry import (
    BACKEND_NAMES,
    BACKENDS,
    capable,
    create_gl_context,
    create_renderer,
    get_renderer,
    render,
    resolve_backend,
)
from .trace import PixelTrace, SampleTrace, TraceStep, trace_pixel
from .types import SORT_ENTRY_BYTES, Frame, FrameStats, Mode, RenderSettings

__all__ = [
    "AUTO",
    "BACKENDS",
    "BACKEND_NAMES",
    "SORT_ENTRY_BYTES",
    "BackendChoice",
    "Capabilities",
    "CpuRenderer",
    "CudaRenderer",
    "Frame",
    "FrameStats",
    "Mode",
    "PixelTrace",
    "RenderSettings",
    "Renderer",
    "SampleTrace",
    "TraceStep",
    "build_info",
    "capable",
    "choose_backend",
    "compiler_line",
    "create_gl_context",
    "create_renderer",
    "get_renderer",
    "render",
    "resolve_backend",
    "simd_line",
    "trace_pixel",
]
