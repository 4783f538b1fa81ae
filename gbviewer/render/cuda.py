"""The CUDA backend: gbviewer._native_cuda (built from native/cuda when a CUDA toolkit is present)."""

from __future__ import annotations

import threading
import time

import numpy as np

from ..camera import Camera
from ..cells import Cells
from ..errors import BackendUnavailable, RenderError
from ..scene import Scene
from .control import Progress, RenderControl
from .prepare import Prepared, camera_args, native_frame, prepare
from .types import Frame, RenderSettings


class CudaRenderer:
    """Native CUDA backend: the scene stays on the device (a trained Duplex-GS model's view is uploaded per frame).

    Threads may share one renderer: uploads and renders are serialised (a lock here around the scene and cells on
    the device, and a mutex in the native renderer around its buffers)."""

    name = "cuda"

    def __init__(self, device: int = -1) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cuda backend unavailable: {why}")
        from .. import _native_cuda

        self._lock = threading.Lock()
        self._scene: Scene | None = None
        self._uploaded: Scene | None = None
        self._cells: Cells | None = None
        try:
            self._impl = _native_cuda.Renderer(device)
        except RuntimeError as exc:
            raise BackendUnavailable(f"cuda backend unavailable: {exc}") from None

    @classmethod
    def available(cls) -> tuple[bool, str]:
        try:
            from .. import _native_cuda
        except ImportError:
            return False, "not built: no CUDA toolkit (nvcc) was found when gbviewer was installed"
        ok, why = _native_cuda.availability()
        return ok, "" if ok else why

    def upload(self, scene: Scene) -> None:
        with self._lock:
            self._scene = scene
            self._uploaded = None
            self._cells = None
            if scene.oit is None or scene.oit.neural is None:
                self._upload(scene)

    def _upload(self, scene: Scene) -> None:
        # Forget what is on the device first: a failed upload (out of device memory) leaves no scene there.
        self._uploaded = None
        self._cells = None
        try:
            self._impl.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d)
            if scene.oit is not None and scene.oit.view_weight_sh is not None:
                self._impl.upload_weights(np.ascontiguousarray(scene.oit.view_weight_sh, np.float32))
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None
        self._uploaded = scene

    def _sync(self, prep: Prepared) -> None:
        """Put the view's splats and duplex cells on the device where they are not yet. Called with the lock held."""
        scene, cells = prep.scene, prep.cells
        if scene is not self._uploaded:
            self._upload(scene)
        if cells is not None and cells is not self._cells:
            self._cells = None
            try:
                self._impl.upload_cells(cells.means, cells.scales, cells.quats, cells.offsets, cells.members,
                                        cells.cell_of(scene.num_splats))
            except RuntimeError as exc:
                raise RenderError(f"cuda: {exc}") from None
            self._cells = cells

    def render(self, camera: Camera, settings: RenderSettings, *, cancel: threading.Event | None = None,
               on_progress: Progress | None = None, partial: np.ndarray | None = None) -> Frame:
        """One kernel sequence per frame: `cancel` is checked before and after it, progress is 0 then 1 of 1,
        `partial` receives the frame at the end."""
        t0 = time.perf_counter()
        with self._lock, RenderControl(cancel, on_progress, partial) as control:
            control.check_partial(camera.width, camera.height)
            prep = prepare(self._scene, camera, settings, self.name)
            self._sync(prep)
            control.step(0, 1)
            try:
                out = self._impl.render(*camera_args(camera), int(settings.mode), settings.supersample,
                                        settings.sh_degree, np.asarray(settings.background, np.float32),
                                        settings.debug == "window", *(prep.oit or ()))
            except RuntimeError as exc:
                raise RenderError(f"cuda: {exc}") from None
            control.step(1, 1)
        frame = native_frame(out, prep, camera, settings, self.name, t0)
        control.fill_partial(frame.image)
        return frame
