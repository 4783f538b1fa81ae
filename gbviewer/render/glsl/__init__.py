"""The GLSL compute backend (OpenGL 4.3 through moderngl): `renderer` (the pipeline), `context` (contexts, shader
sources), `gpu` (buffers and programs), `sort` (scan, radix sort, tile binning), `limits` (drivers that cap loops)."""

from .context import SHADER_DIR, shader_source, standalone_context
from .renderer import GlslRenderer

__all__ = ["SHADER_DIR", "GlslRenderer", "shader_source", "standalone_context"]
