"""The GLSL compute backend (OpenGL 4.3 through moderngl): `renderer` (the pipeline), `stage` (the camera's uniforms,
the per-camera stage), `binning` (tile lists), `blend` (blend.comp's variants and dispatches), `interface` (counter
slots and record sizes, read from shaders/interface.glsl), `context` (contexts, shader sources), `gpu` (buffers and
programs), `sort` (scan, radix sort, pair sort), `limits` (drivers that cap loops), `lod` (a cut drawn in place)."""

from .context import SHADER_DIR, shader_source, standalone_context
from .renderer import GlslRenderer

__all__ = ["SHADER_DIR", "GlslRenderer", "shader_source", "standalone_context"]
