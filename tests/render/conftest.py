"""The render tests' fixtures: `gl`, the GLSL backend's OpenGL context (glsl_helpers.py)."""

from glsl_helpers import gl  # noqa: F401 (a fixture: pytest finds it in this conftest)
