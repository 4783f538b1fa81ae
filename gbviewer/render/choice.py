"""`backend="auto"`: the fastest backend this machine runs, decided once per process, with the reason.

CUDA where its module imports and a device is usable; else GLSL where a headless OpenGL 4.3 context comes from a
hardware driver (a software rasterizer such as Mesa's llvmpipe runs the compute shaders slower than the CPU backend);
else the CPU. The probes never raise: each failure becomes part of the reason. The OpenGL probe runs in a thread of
its own, so the caller's current context (a window's, say) stays as it was.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Mapping
from dataclasses import dataclass

from ..core.errors import BackendUnavailable
from .cuda import CudaRenderer
from .glsl.context import GL_REQUIRED, create_context

AUTO = "auto"
FALLBACK = "cpu"  # what auto picks where nothing faster is usable, and what runs where a pick cannot
GL_PROBE_TIMEOUT_S = 20.0  # a driver that hangs while creating a context counts as no OpenGL
SOFTWARE_GL = re.compile(r"llvmpipe|softpipe|swrast|lavapipe|swiftshader|software|basic render|gdi generic", re.I)


@dataclass(frozen=True)
class BackendChoice:
    """The backend `auto` renders on and why (e.g. 'CUDA unavailable (no CUDA device found); OpenGL is llvmpipe
    (LLVM 15.0.6, 256 bits), a software rasterizer slower than the CPU backend')."""

    name: str
    reason: str

    def __str__(self) -> str:
        return f"{self.name} (auto: {self.reason})"


@dataclass(frozen=True)
class GlProbe:
    """What a headless OpenGL context reports: GL_RENDERER and version (430 = 4.3), or why there is none."""

    renderer: str = ""
    version: int = 0
    error: str = ""

    @classmethod
    def of(cls, ctx, error: str = "") -> GlProbe:
        """The probe of a moderngl context (None: no context, for `error`)."""
        if ctx is None:
            return cls(error=error or "no context")
        return cls(str(ctx.info.get("GL_RENDERER", "?")), int(ctx.version_code))

    @property
    def software(self) -> bool:
        return bool(SOFTWARE_GL.search(self.renderer))


def probe_cuda() -> tuple[bool, str]:
    """(usable, why not): the CUDA module imports and reports a usable device."""
    try:
        return CudaRenderer.available()
    except Exception as exc:  # noqa: BLE001 - a broken driver or module must not take the caller down
        return False, f"{type(exc).__name__}: {exc}"


def probe_gl() -> GlProbe:
    """A headless context created, read and released in a short-lived thread of its own."""
    found: list[GlProbe] = []

    def run() -> None:
        try:
            ctx = create_context()
        except BackendUnavailable as exc:
            found.append(GlProbe(error=str(exc)))
            return
        except Exception as exc:  # noqa: BLE001 - no display, no EGL, a driver's own exception
            found.append(GlProbe(error=f"no OpenGL context: {type(exc).__name__}: {exc}"))
            return
        try:
            found.append(GlProbe.of(ctx))
        finally:
            ctx.release()

    thread = threading.Thread(target=run, name="gbviewer-gl-probe", daemon=True)
    thread.start()
    thread.join(GL_PROBE_TIMEOUT_S)
    return found[0] if found else GlProbe(error=f"no OpenGL context within {GL_PROBE_TIMEOUT_S:g} s")


def decide(cuda: tuple[bool, str], gl: GlProbe | None, failed: Mapping[str, str] | None = None) -> BackendChoice:
    """The choice from the probes' results (`gl` None: not probed, as CUDA is usable). `failed`: backends that
    stopped working in this process (name -> why, `Renderer.usable()`), passed over for the next one."""
    failed = failed or {}
    if "glsl" in failed:
        gl = GlProbe(error=f"glsl stopped working ({failed['glsl']})")
    ok, why = (False, f"stopped working: {failed['cuda']}") if "cuda" in failed else cuda
    if ok:
        return BackendChoice("cuda", "a CUDA device is usable")
    no_cuda = f"CUDA unavailable ({why.removeprefix('cuda backend unavailable: ')})"
    if gl is None or gl.error:
        why_not = gl.error.removeprefix("glsl backend unavailable: ") if gl else "OpenGL not probed"
        return BackendChoice(FALLBACK, f"{no_cuda}; {why_not}")
    if gl.software:
        return BackendChoice(
            FALLBACK, f"{no_cuda}; OpenGL is {gl.renderer}, a software rasterizer slower than the CPU backend"
        )
    if gl.version < GL_REQUIRED:
        return BackendChoice(
            FALLBACK,
            f"{no_cuda}; OpenGL {gl.version / 100:.1f} on {gl.renderer} has no compute "
            f"shaders ({GL_REQUIRED / 100:.1f} needed)",
        )
    return BackendChoice("glsl", f"{no_cuda}; OpenGL {gl.version / 100:.1f} on {gl.renderer}")


def decide_measured(
    status: Mapping[str, tuple[bool, str]], ctx, failed: Mapping[str, str] | None = None
) -> BackendChoice:
    """The choice from backends probed elsewhere: `status` name -> (usable, why) and `ctx` the OpenGL context
    they were probed in (None: none could be made), as the viewer's render thread measures them."""
    missing = (False, "not part of this installation")
    return decide(status.get("cuda", missing), GlProbe.of(ctx, status.get("glsl", missing)[1]), failed)


_choice: list[BackendChoice] = []
_lock = threading.Lock()


def choose_backend() -> BackendChoice:
    """The backend `auto` picks in this process and why: probed on the first call (CUDA, then OpenGL only when
    CUDA is not usable), remembered after it."""
    with _lock:
        if not _choice:
            cuda = probe_cuda()
            _choice.append(decide(cuda, None if cuda[0] else probe_gl()))
        return _choice[0]


def forget_choice() -> None:
    """Probe again on the next `choose_backend()` (after installing a driver, and in tests)."""
    with _lock:
        _choice.clear()
