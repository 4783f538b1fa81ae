"""OpenGL contexts of the glsl backend (a process-wide headless EGL one, or the caller's) and the shader sources."""

from __future__ import annotations

import re
import sys
from pathlib import Path

from ...core.errors import BackendUnavailable

GL_REQUIRED = 430
SHADER_DIR = Path(__file__).resolve().parents[2] / "shaders"  # installed: gbviewer/shaders (CMake puts them there)
if not SHADER_DIR.is_dir():  # running from a source checkout: shaders/ is at the repository top
    SHADER_DIR = Path(__file__).resolve().parents[3] / "shaders"

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)


def shader_source(name: str, defines: dict[str, object] | None = None) -> str:
    """The GLSL 4.30 source of shaders/`name` with its #include "file" lines expanded (each file once)."""
    seen: set[str] = set()

    def expand(fname: str) -> str:
        if fname in seen:
            return ""
        seen.add(fname)
        path = SHADER_DIR / fname
        try:
            text = path.read_text()
        except OSError as exc:
            raise BackendUnavailable(f"glsl backend: shader {path} not found ({exc}); reinstall gbviewer") from None
        return _INCLUDE.sub(lambda m: expand(m.group(1)), text)

    head = "#version 430\n" + "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return head + expand(name)


def _new_context():
    import moderngl

    kwargs = {"standalone": True, "require": GL_REQUIRED}
    if sys.platform.startswith("linux"):
        kwargs["backend"] = "egl"
    return moderngl.create_context(**kwargs)


def create_context():
    """A new headless context, current in the calling thread; raises BackendUnavailable with the reason."""
    if sys.platform == "darwin":
        raise BackendUnavailable(
            f"glsl backend unavailable: macOS has no OpenGL {GL_REQUIRED // 100}."
            f"{GL_REQUIRED % 100 // 10} (its OpenGL ends at 4.1, without compute shaders): "
            "use the cpu backend"
        )
    try:
        import moderngl  # noqa: F401
    except ImportError as exc:
        raise BackendUnavailable(
            f"glsl backend unavailable: moderngl is not installed ({exc}); pip install 'moderngl>=5.8'"
        ) from None
    try:
        return _new_context()
    except Exception as exc:  # noqa: BLE001 - glcontext raises plain Exceptions with the driver's message
        msg = str(exc).strip() or type(exc).__name__
        raise BackendUnavailable(
            f"glsl backend unavailable: no OpenGL {GL_REQUIRED // 100}.{GL_REQUIRED % 100 // 10} context: {msg} "
            "(headless Linux needs EGL and Mesa: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)"
        ) from None


_standalone: dict[str, object] = {}


def standalone_context():
    """The process-wide headless context (created on first use), made current in the calling thread; raises
    BackendUnavailable with the reason."""
    if "ctx" not in _standalone and "error" not in _standalone:
        try:
            _standalone["ctx"] = create_context()
        except BackendUnavailable as exc:
            _standalone["error"] = exc
    if "ctx" in _standalone:
        ctx = _standalone["ctx"]
        ctx.__enter__()
        return ctx
    raise BackendUnavailable(str(_standalone["error"]))


def release_current() -> None:
    """Leave no headless context current in the calling thread: a window's GLX context cannot become current in a
    thread where an EGL one is (X error BadAccess, which ends the process). The glsl renderer makes its context
    current again before it works."""
    ctx = _standalone.get("ctx")
    if ctx is not None:
        ctx.__exit__(None, None, None)


def check_context(ctx) -> None:
    """Raise BackendUnavailable unless the context has OpenGL 4.3 (compute shaders)."""
    if ctx.version_code < GL_REQUIRED:
        raise BackendUnavailable(
            f"glsl backend unavailable: the context is OpenGL {ctx.version_code / 100:.1f} "
            f"({ctx.info.get('GL_RENDERER', '?')}); compute shaders need OpenGL 4.3"
        )
