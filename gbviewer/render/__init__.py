"""Rendering: the types every backend shares (`types`), the per-frame preparation (`prepare`), the backends
(`cpu`, `cuda`, `glsl/`), the registry that creates them by name (`get_renderer`, `render`) and the pixel trace of
the CPU kernel (`trace`)."""

from .cpu import CpuRenderer
from .cuda import CudaRenderer
from .registry import BACKENDS, create_gl_context, create_renderer, get_renderer, render
from .trace import PixelTrace, SampleTrace, TraceStep, trace_pixel
from .types import SORT_ENTRY_BYTES, Frame, FrameStats, Mode, Renderer, RenderSettings

__all__ = [
    "BACKENDS", "SORT_ENTRY_BYTES", "CpuRenderer", "CudaRenderer", "Frame", "FrameStats", "Mode", "PixelTrace",
    "RenderSettings", "Renderer", "SampleTrace", "TraceStep", "create_gl_context", "create_renderer", "get_renderer",
    "render", "trace_pixel",
]
