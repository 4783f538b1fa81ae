"""How a pane's frame gets from the renderer to the window: the copy path and the GPU display path.

copy: the render thread returns the frame in host memory (cpu; glsl on the render thread's own headless EGL context,
read back; cuda, copied back) and the UI thread uploads it into the pane's texture (`panes`). The path for llvmpipe,
Mesa's software OpenGL (its "GPU" memory is host memory anyway), and the only one for the cpu backend.

gpu: the frame is drawn from GPU memory, as SIBR and the INRIA viewers do. The render thread holds an OpenGL context
that shares objects with the window's (a hidden glfw window's, made on the UI thread at startup: `SharedContext`);
glsl renders into a display texture of that context and cuda writes one through CUDA-GL interop
(`render_to_texture`), and the UI draws that texture by its GL name (`GpuFrame.texture`). Features that need the
pixels on the CPU (a pane screenshot, a refining cpu frame's underlay, comparisons) read them back from the texture
on demand, once per frame, in the UI thread (`GpuFrame.rgb`); debug views (alpha, evals, window, ...) ask for a
copy-path render of their pane instead (the display texture holds colour and alpha only).

`GBVIEWER_DISPLAY_PATH=auto|gpu|copy` (default auto): auto takes the GPU path where the window's OpenGL is a hardware
driver (not llvmpipe, softpipe or swrast) and the backend can (glsl: OpenGL 4.3 on the shared context; cuda: that
context runs on a CUDA device); gpu forces it on a software driver too (the tests do, on llvmpipe); copy never.

Synchronisation: the render thread finishes its GL (and CUDA) work before it posts a frame, and the UI binds the
texture again each time it draws it, which makes the writes visible in its context. A texture whose frame the UI
dropped comes back through a fence set in the UI thread after its last draw with it (`fence_retired`), and the render
thread waits for that fence before writing the texture again.
"""

from __future__ import annotations

import ctypes
import os
import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...render import Frame, FrameStats

ENV = "GBVIEWER_DISPLAY_PATH"
REQUESTS = ("auto", "gpu", "copy")
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software rasterizer", "gdi generic")
MAX_FREE = 4  # display textures kept for reuse once the UI is done with them (the others are deleted)
FENCE_WAIT_NS = 1_000_000_000  # per glClientWaitSync call; a fence that never signals costs its texture


def requested_path(env: dict | None = None) -> tuple[str, str]:
    """GBVIEWER_DISPLAY_PATH as (auto | gpu | copy, warning); unset is auto, an unknown value auto with a warning."""
    value = (os.environ if env is None else env).get(ENV, "").strip().lower()
    if not value or value in REQUESTS:
        return value or "auto", ""
    return "auto", f"{ENV}={value!r} is not one of {', '.join(REQUESTS)}: using auto"


def is_software(renderer: str) -> bool:
    """Whether a GL_RENDERER string names a software rasteriser."""
    return any(name in renderer.lower() for name in SOFTWARE_RENDERERS)


def describe(path: str) -> str:
    return {"gpu": "drawn from GPU memory", "copy": "copied through host memory"}.get(path, path)


# ---- the shared context -------------------------------------------------------------------------------------------


@dataclass(eq=False)
class SharedContext:
    """The hidden glfw window whose OpenGL 4.3 context shares objects with the viewer window's (None, and why not,
    where the GPU display path is off). Made and destroyed on the UI thread; its context is current in the render
    thread."""

    request: str
    window: Any = None
    why: str = ""

    @classmethod
    def open(cls, main_window, gl_renderer: str, request: str) -> "SharedContext":
        """For the window `main_window` (current in this, the UI, thread, and left current)."""
        if request == "copy":
            return cls(request, None, f"{ENV}=copy")
        if request == "auto" and is_software(gl_renderer):
            return cls(
                request, None, f"{gl_renderer} renders in software: frames are copied ({ENV}=gpu forces the GPU path)"
            )
        import glfw

        glfw.default_window_hints()
        for hint, value in (
            (glfw.CONTEXT_VERSION_MAJOR, 4),
            (glfw.CONTEXT_VERSION_MINOR, 3),
            (glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE),
            (glfw.OPENGL_FORWARD_COMPAT, True),
            (glfw.VISIBLE, False),
            (glfw.FOCUSED, False),
        ):
            glfw.window_hint(hint, value)
        window = glfw.create_window(1, 1, "gbviewer render", None, main_window)
        glfw.default_window_hints()
        glfw.make_context_current(main_window)
        if not window:
            _, desc = glfw.get_error()
            desc = desc.decode(errors="replace") if isinstance(desc, bytes) else str(desc or "no reason given")
            return cls(request, None, f"no OpenGL 4.3 context sharing the window's ({desc}): frames are copied")
        return cls(request, window)

    def make_current(self):
        """Render thread: the shared context current in it, as a moderngl.Context."""
        import glfw
        import moderngl

        glfw.make_context_current(self.window)
        return moderngl.create_context()

    def done_current(self) -> None:
        """Render thread: no context current any more (before the UI destroys the window)."""
        import glfw

        glfw.make_context_current(None)

    def close(self) -> None:
        """UI thread, after the render thread stopped."""
        if self.window is not None:
            import glfw

            glfw.destroy_window(self.window)
            self.window = None


# ---- fences (glFenceSync & co. through glfw's loader: moderngl has none) -------------------------------------------

_GL: dict[str, Any] = {}
GL_SYNC_GPU_COMMANDS_COMPLETE = 0x9117
GL_TIMEOUT_EXPIRED = 0x911B
GL_WAIT_FAILED = 0x911D


def _gl(name: str):
    """An OpenGL function (resolved once, with a context current)."""
    if not _GL:
        import glfw

        def fn(n: str, restype, *args):
            addr = glfw.get_proc_address(n)
            if not addr:
                raise RuntimeError(f"{n} is not available")
            return ctypes.CFUNCTYPE(restype, *args)(addr)

        _GL.update(
            glFenceSync=fn("glFenceSync", ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint),
            glClientWaitSync=fn("glClientWaitSync", ctypes.c_uint, ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint64),
            glDeleteSync=fn("glDeleteSync", None, ctypes.c_void_p),
            glFlush=fn("glFlush", None),
        )
    return _GL[name]


def fence() -> int:
    """A fence after every command of the current context so far (flushed, so another context can wait for it)."""
    sync = _gl("glFenceSync")(GL_SYNC_GPU_COMMANDS_COMPLETE, 0)
    _gl("glFlush")()
    return sync


def wait_and_delete(sync: int) -> bool:
    """Wait (on the CPU) until the fence has signalled, then delete it; False when it did not."""
    try:
        for _ in range(5):
            status = _gl("glClientWaitSync")(sync, 0, FENCE_WAIT_NS)
            if status not in (GL_TIMEOUT_EXPIRED, GL_WAIT_FAILED):
                return True
            if status == GL_WAIT_FAILED:
                return False
        return False
    finally:
        _gl("glDeleteSync")(sync)


# ---- display textures and the frames in them ----------------------------------------------------------------------


class DisplayTextures:
    """The GPU display path's textures (RGBA32F): made, reused and deleted by the render thread on the shared
    context; each is shown through a `GpuFrame`, and comes back when that frame is garbage (fenced by the UI
    thread: `fence_retired`). Free textures are kept for reuse (at most MAX_FREE) while the renders use the GPU path,
    and deleted when they do not."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._retired: list[tuple[int, list]] = []  # (GL name, the UI's wrapper holder) of dropped frames
        self._returned: list[tuple[list[int], int]] = []  # (GL names, the UI's fence after its last use of them)
        self._live: dict[int, Any] = {}  # GL name -> moderngl texture of the render thread's context
        self._free: list[int] = []
        self.on_delete: Callable[[int], None] | None = None  # before a texture is deleted (cuda drops its registration)

    @property
    def live(self) -> int:
        return len(self._live)

    # ---- any thread, UI thread

    def _retire(self, glo: int, holder: list) -> None:
        with self._lock:
            self._retired.append((glo, holder))

    def fence_retired(self) -> bool:
        """UI thread: release the wrappers of the dropped frames' textures and hand the textures back behind one
        fence; whether there were any."""
        with self._lock:
            retired, self._retired = self._retired, []
        if not retired:
            return False
        for _, holder in retired:
            if holder[0] is not None:
                holder[0].release()  # an external texture: the wrapper goes, the GL texture stays
                holder[0] = None
        sync = fence()
        with self._lock:
            self._returned.append(([glo for glo, _ in retired], sync))
        return True

    # ---- render thread

    def acquire(self, ctx, width: int, height: int):
        """A texture of width x height that no frame shows: a free one, or a new one."""
        for glo in self._free:
            tex = self._live[glo]
            if tex.size == (width, height):
                self._free.remove(glo)
                return tex
        import moderngl

        tex = ctx.texture((width, height), 4, dtype="f4")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._live[tex.glo] = tex
        return tex

    def discard(self, tex) -> None:
        """A texture acquired for a frame that was not made (cancelled, failed): free again."""
        self._free.append(tex.glo)

    def frame(self, tex, stats: FrameStats) -> "GpuFrame":
        return GpuFrame(stats, tex.glo, tex.size, self)

    def recycle(self, keep: bool) -> None:
        """Take back the textures the UI returned (waiting for its fences); keep up to MAX_FREE free ones when
        `keep`, else delete them all."""
        with self._lock:
            returned, self._returned = self._returned, []
        for names, sync in returned:
            if wait_and_delete(sync):
                self._free.extend(names)
            else:
                for glo in names:
                    self._delete(glo)
        while self._free and (not keep or len(self._free) > MAX_FREE):
            self._delete(self._free.pop(0))

    def release_all(self) -> None:
        """Delete every texture, shown or not (the render thread stops)."""
        with self._lock:
            returned, self._returned = self._returned, []
        for _, sync in returned:
            _gl("glDeleteSync")(sync)
        for glo in list(self._live):
            self._delete(glo)
        self._free.clear()

    def _delete(self, glo: int) -> None:
        if self.on_delete is not None:
            self.on_delete(glo)
        self._live.pop(glo).release()


class GpuFrame(Frame):
    """A frame whose pixels are in a display texture (RGBA32F: rgb, alpha; row 0 the image's top). `stats` as any
    frame's, no debug planes; `rgb` and `alpha` are read back from the texture the first time they are asked for,
    in the UI thread, through the window's context (`texture(ctx)` first). The texture is the frame's for as long as
    the frame lives; then it goes back to the render thread."""

    readbacks = 0  # GPU frames read back in this process (the display path itself reads none)

    def __init__(self, stats: FrameStats, glo: int, size: tuple[int, int], textures: DisplayTextures) -> None:
        self.stats = stats
        self.debug: dict[str, np.ndarray] = {}
        self.glo, self.size = glo, size
        self._planes: tuple[np.ndarray, np.ndarray] | None = None
        self._ui: list = [None, None]  # the window context's wrapper of the texture, the UI thread's id
        weakref.finalize(self, textures._retire, glo, self._ui)

    def __repr__(self) -> str:
        return f"GpuFrame(texture {self.glo}, {self.size[0]}x{self.size[1]}, on_cpu={self.on_cpu})"

    def texture(self, ctx):
        """UI thread: the frame's texture as a moderngl texture of the window's context `ctx`."""
        if self._ui[0] is None:
            self._ui[:] = [ctx.external_texture(self.glo, self.size, 4, 0, "f4"), threading.get_ident()]
        return self._ui[0]

    @property
    def on_cpu(self) -> bool:
        """Whether the pixels were read back."""
        return self._planes is not None

    @property
    def rgb(self) -> np.ndarray:
        return self._read()[0]

    @property
    def alpha(self) -> np.ndarray:
        return self._read()[1]

    def _read(self) -> tuple[np.ndarray, np.ndarray]:
        if self._planes is None:
            wrapper, thread = self._ui
            if wrapper is None or thread != threading.get_ident():
                raise RuntimeError("a GPU frame's pixels are read in the UI thread, once the window showed it")
            w, h = self.size
            img = np.frombuffer(wrapper.read(), np.float32).reshape(h, w, 4)
            self._planes = (img[:, :, :3].copy(), img[:, :, 3].copy())
            GpuFrame.readbacks += 1
        return self._planes
