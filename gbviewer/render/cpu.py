"""The CPU backend: the native C++/OpenMP module gbviewer._native (built from native/cpu)."""

from __future__ import annotations

import threading
import time

import numpy as np

from ..camera import Camera
from ..errors import BackendUnavailable
from ..scene import Scene
from .control import Progress, RenderControl
from .prepare import Prepared, camera_args, native_frame, prepare
from .trace import PixelTrace, from_native
from .types import Capabilities, Frame, Renderer, RenderSettings


def _native_extra(prep: Prepared) -> dict:
    """Keyword arguments of the native render call for wsr and duplex (globals, view weights, cells)."""
    if prep.oit is None:
        return {}
    extra = dict(prep.oit._asdict(), weight_sh=prep.scene.oit.view_weight_sh if prep.scene.oit else None)
    cells = prep.cells
    if cells is not None:
        extra.update(cell_means=cells.means, cell_scales=cells.scales, cell_quats=cells.quats,
                     cell_offsets=cells.offsets, cell_members=cells.members)
    return extra


class CpuRenderer(Renderer):
    """Native C++/OpenMP backend (gbviewer._native)."""

    name = "cpu"
    capabilities = Capabilities(progressive=True, trace=True, simd=True, host=True)

    def __init__(self) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cpu backend unavailable: {why}")
        from .. import _native

        self._native = _native
        self._scene: Scene | None = None
        self._sh: np.ndarray | None = None

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
        if scene is not self._scene:
            self._native.release_buffers()  # the per-frame buffers the native module keeps for the last scene
        self._scene = scene
        self._sh = np.ascontiguousarray(scene.sh, np.float32)  # the native module reads float32 (float16: a copy)

    def release(self) -> None:
        self._native.release_buffers()
        self._scene = self._sh = None

    def _native_render(self, prep: Prepared, camera: Camera, settings: RenderSettings, **kwargs) -> dict:
        """The native module's render call for this frame; kwargs: control or trace."""
        scene = prep.scene
        return self._native.render(
            scene.means, scene.scales, scene.quats, scene.opacities, self._sh if scene is self._scene else scene.sh,
            scene.filter_3d,
            *camera_args(camera), int(settings.mode), settings.supersample, settings.sh_degree,
            np.asarray(settings.background, np.float32), settings.debug == "window", settings.threads,
            **_native_extra(prep), **kwargs,
        )

    def render(self, camera: Camera, settings: RenderSettings, *, cancel: threading.Event | None = None,
               on_progress: Progress | None = None, partial: np.ndarray | None = None) -> Frame:
        t0 = time.perf_counter()
        control = RenderControl(cancel, on_progress, partial)
        control.check_partial(camera.width, camera.height)
        prep = prepare(self._scene, camera, settings, self.name)
        with control:
            out = self._native_render(prep, camera, settings, control=control.block if control.active else None,
                                      partial=partial)
        control.check()  # the native render skipped its remaining tiles once the event was set
        return native_frame(out, prep, camera, settings, self.name, t0)

    def trace(self, camera: Camera, settings: RenderSettings, x: int, y: int) -> PixelTrace:
        """The pixel trace of (x, y) in this frame (gbviewer.render.trace; `trace_pixel` checks the pixel)."""
        prep = prepare(self._scene, camera, settings, self.name)
        return from_native(self._native_render(prep, camera, settings, trace=(x, y)), settings, camera, x, y)
