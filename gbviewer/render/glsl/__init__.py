"""The GLSL compute backend (OpenGL 4.3 through moderngl): `renderer` (the pipeline), `binning` (tile lists),
`interface` (counter slots and record sizes, read from shaders/interface.glsl), `context` (contexts, shader sources),
`gpu` (buffers and programs), `sort` (scan, radix sort, pair sort), `limits` (drivers that cap loops)."""

from .context import SHADER_DIR, shader_source, standalone_context
from .renderer import GlslRenderer

__all__ = ["SHADER_DIR", "GlslRenderer", "shader_source", "standalone_context"]
