"""The CPU backend: the native C++/OpenMP renderer gbviewer._native.Renderer (built from native/cpu)."""

from __future__ import annotations

import time

import numpy as np

from ..camera import Camera
from ..cancel import Cancellable
from ..cells import Cells
from ..errors import BackendUnavailable
from ..scene import Scene
from .control import FrameLock, Progress, RenderControl
from .prepare import NativeUploads, camera_args, native_frame, prepare
from .trace import PixelTrace, from_native
from .types import Capabilities, Frame, Renderer, RenderSettings


class CpuRenderer(NativeUploads, Renderer):
    """Native C++/OpenMP backend: the scene is uploaded once (the native renderer references its arrays); a trained
    Duplex-GS model's view is uploaded per frame, duplex cells when they change.

    Threads may share one renderer: frames are serialised (a lock here around the uploaded scene and cells, and a
    mutex in the native renderer around its buffers); each frame runs on every core."""

    name = "cpu"
    capabilities = Capabilities(progressive=True, trace=True, simd=True, host=True)

    def __init__(self) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cpu backend unavailable: {why}")
        from .. import _native

        self._impl = _native.Renderer()
        self._lock = FrameLock()
        self._scene: Scene | None = None
        self._uploaded: Scene | None = None
        self._cells: Cells | None = None

    @classmethod
    def available(cls) -> tuple[bool, str]:
        try:
            from .. import _native  # noqa: F401
        except ImportError as exc:
            if "GBVIEWER_SIMD" in str(exc):  # the environment forces a SIMD path this CPU or build lacks
                return False, str(exc)
            return False, f"native module not built ({exc}); reinstall with pip install ."
        return True, ""

    def upload(self, scene: Scene) -> None:
        with self._lock:
            if scene is self._scene:
                return
            self._impl.release_buffers()  # sized for the last scene
            self._scene, self._uploaded, self._cells = scene, None, None
            if scene.oit is None or scene.oit.neural is None:
                self._upload(scene)

    def release(self) -> None:
        with self._lock:
            self._impl.release_buffers()
            self._scene = self._uploaded = self._cells = None

    @staticmethod
    def _frame_args(camera: Camera, settings: RenderSettings) -> tuple:
        """The native call's camera, mode, supersampling, SH cap, background; the oit globals follow."""
        return (*camera_args(camera), int(settings.mode), settings.supersample, settings.sh_degree,
                np.asarray(settings.background, np.float32))

    def render(self, camera: Camera, settings: RenderSettings, *, cancel: Cancellable | None = None,
               on_progress: Progress | None = None, partial: np.ndarray | None = None) -> Frame:
        t0 = time.perf_counter()
        control = RenderControl(cancel, on_progress, partial)
        control.check_partial(camera.width, camera.height)
        control.check()  # before any work (a trained model's decode included)
        with self._lock:
            prep = prepare(self._scene, camera, settings, self.name)
            self._sync(prep)
            out = self._impl.render(*self._frame_args(camera, settings), settings.debug == "window",
                                    *(prep.oit or ()), threads=settings.threads, cancel=control.flag,
                                    on_progress=control.hook, partial=partial,
                                    view_filter=settings.view_filter.native())
        control.check(out["cancelled"])  # the native render skipped its remaining work once it saw the flag
        return native_frame(out, prep, camera, settings, self.name, t0)

    def trace(self, camera: Camera, settings: RenderSettings, x: int, y: int) -> PixelTrace:
        """The pixel trace of (x, y) in this frame (gbviewer.render.trace; `trace_pixel` checks the pixel)."""
        with self._lock:
            prep = prepare(self._scene, camera, settings, self.name)
            self._sync(prep)
            out = self._impl.trace(*self._frame_args(camera, settings), *(prep.oit or ()), x=x, y=y,
                                   view_filter=settings.view_filter.native())
        return from_native(out, settings, camera, x, y)
