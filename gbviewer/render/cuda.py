"""The CUDA backend: gbviewer._native_cuda (built from native/cuda when a CUDA toolkit is present)."""

from __future__ import annotations

import threading
import time

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import BackendFailed, BackendUnavailable, RenderError
from ..lod import Hierarchy
from ..model.camera import Camera
from ..model.cells import Cells
from ..model.scene import Scene
from .contract import Capabilities, Renderer
from .control import Progress, RenderControl
from .cuda_textures import TextureRegistrations
from .prepare import (
    CutRows,
    NativeUploads,
    Prepared,
    camera_args,
    check_display_texture,
    native_frame,
    native_stats,
    prepare,
)
from .types import Frame, FrameStats, RenderSettings


class CudaRenderer(NativeUploads, Renderer):
    """Native CUDA backend: the scene stays on the device (a trained Duplex-GS model's view is uploaded per frame).
    A level-of-detail cut is drawn in place: the hierarchy's interior nodes go up once after the scene's rows, and a
    cut's row list (made here: `CutRows`) only when it changes.

    Threads may share one renderer: uploads and renders are serialised (a lock here around the scene and cells on
    the device, and a mutex in the native renderer around its buffers).

    A CUDA error that leaves the device unusable (a fault in a kernel, a watchdog timeout, the device lost) raises
    BackendFailed and marks the renderer unusable (`Renderer.failed`, `usable()`): every later call raises
    BackendFailed with that reason, `get_renderer` replaces it, and `available()` says no for the rest of the
    process."""

    name = "cuda"
    capabilities = Capabilities(gl_texture=True, shared_stage=True)

    def __init__(self, device: int = -1) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cuda backend unavailable: {why}")
        from .. import _native_cuda

        try:
            impl = _native_cuda.Renderer(device)
        except RuntimeError as exc:
            raise BackendUnavailable(f"cuda backend unavailable: {exc}") from None
        self._attach(impl, _native_cuda.DeviceFailed)

    def _attach(self, impl, device_failed: type[Exception]) -> None:
        """The wrapper's state around the native renderer `impl`, whose `device_failed` errors mean its device
        failed (the tests attach a stand-in)."""
        self._lock = threading.Lock()
        self._impl = impl
        self._device_failed = device_failed
        self._failure = None
        self._scene: Scene | None = None
        self._uploaded: Scene | None = None
        self._cells: Cells | None = None
        self._cut = CutRows()
        self._textures = TextureRegistrations(self._release)

    def _native(self, method: str, *args, **kwargs):
        """The native renderer's `method(*args, **kwargs)`: RuntimeError -> RenderError, DeviceFailed -> BackendFailed
        (and the renderer unusable from then on)."""
        if self._failure is not None:
            raise BackendFailed(f"{self.name} backend stopped working: {self._failure}")
        try:
            return getattr(self._impl, method)(*args, **kwargs)
        except self._device_failed as exc:
            raise self.failed(str(exc).splitlines()[0]) from None
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None

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

    def release(self) -> None:
        """Forget the scene and free the device buffers (after a device failure only the scene: the failed
        context's memory goes with the renderer); the texture registrations stay."""
        with self._lock:
            self._scene = self._uploaded = self._cells = None
            if self._failure is None:
                self._native("release_buffers")

    @classmethod
    def gl_interop(cls) -> tuple[bool, str]:
        """Whether `render_to_texture` of a renderer made here with the default device (the process-wide one of
        `get_renderer`) can write into textures of the OpenGL context current in this thread: that context must
        run on the renderer's CUDA device; (usable, reason)."""
        ok, why = cls.available()
        if not ok:
            return False, why
        from .. import _native_cuda

        return interop_status(_native_cuda.gl_devices(), _native_cuda.default_device())

    def render(
        self,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Progress | None = None,
        partial: np.ndarray | None = None,
    ) -> Frame:
        """One kernel sequence per frame: `cancel` is checked before and after it, progress is 0 then 1 of 1,
        `partial` receives the frame at the end."""
        control = RenderControl(cancel, on_progress, partial)
        control.check_partial(camera.width, camera.height)
        out, prep, t0 = self._run(camera, settings, control, "render", extra=(settings.debug == "window",))
        frame = native_frame(out, prep, camera, settings, self.name, t0)
        control.fill_partial(frame.rgb)
        return frame

    def render_to_texture(
        self,
        texture,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Progress | None = None,
    ) -> FrameStats:
        """Render into `texture` (a moderngl RGBA32F texture of the camera's size whose context, or one sharing
        objects with it, is current in this thread and runs on this renderer's device) through CUDA-GL interop:
        rgb and alpha as `render`'s Frame, row 0 the image's top; the pixels never leave the device (the
        evaluation counts are summed there), only the stats come back. No debug planes. The copy has finished when
        it returns. The texture stays registered with CUDA: `release_texture(texture.glo)` before deleting it."""
        check_display_texture(texture, camera, self.name)
        control = RenderControl(cancel, on_progress)
        out, prep, t0 = self._run(camera, settings, control, "render_to_gl_texture", lead=(texture,), extra=(False,))
        texture.ctx.finish()  # the CUDA writes are done; the unmap reaches GL before the UI context samples it
        return native_stats(out, prep, camera, settings, self.name, t0)

    def release_texture(self, glo: int) -> None:
        """Forget the CUDA registration of GL texture `glo` (no-op without one); its context must be current."""
        with self._lock:
            self._textures.forget(glo)

    def _release(self, glo: int) -> None:
        """Drop the native registration of `glo`; also after a device failure (the native renderer then forgets it
        without calling CUDA), so that the viewer can still delete its textures."""
        try:
            self._impl.release_gl_texture(int(glo))
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None

    def _run(
        self,
        camera: Camera,
        settings: RenderSettings,
        control: RenderControl,
        method: str,
        lead: tuple = (),
        extra: tuple = (),
    ) -> tuple:
        """The native renderer's `method(*lead, camera args, mode, ..., background, want_window, oit globals)` under
        the lock (a texture in `lead` passed by its GL name, its registration claimed), `control` checked before and
        after it; its result dict, the frame's inputs and the start time."""
        t0 = time.perf_counter()
        with self._lock, control:
            prep = prepare(self._scene, camera, settings, self.name, lod_in_place=True, flag=control.flag)
            self._sync(prep)
            self._sync_cut(prep, settings.threads, control.flag)
            control.step(0, 1)
            lead = tuple(self._textures.claim(x) for x in lead)
            out = self._native(
                method,
                *lead,
                *camera_args(camera),
                settings.native_mode,
                settings.supersample,
                settings.sh_degree,
                np.asarray(settings.background, np.float32),
                *extra,
                *(prep.oit or ()),
                view_filter=settings.view_filter.native(),
                seed=settings.seed,
                frame=settings.frame,
                cut=prep.tree is not None,
                fast=settings.precision == "fast",
            )
            control.step(1, 1)
        if prep.tree is not None:
            out["lod_splats"] = self._cut.count
        return out, prep, t0

    def _upload_tree(self, t: Hierarchy, sh: np.ndarray) -> None:
        """The hierarchy's interior nodes, rows N.. after the scene's on the device (its cuts are made here)."""
        self._cut.forget()
        self._send("upload_lod", t.means, t.scales, t.quats, t.opacities, sh, t.filter_3d)

    def _sync_cut(self, prep: Prepared, threads: int, flag: np.ndarray) -> None:
        """Upload the frame's level-of-detail cut where it changed (the render then draws it: `cut`)."""
        if prep.tree is not None and self._cut.update(prep.tree, prep.lod, threads, flag):
            try:
                self._send("upload_cut", self._cut.rows, self._cut.weights)
            except BaseException:
                self._cut.forget()  # not on the device: the next frame uploads it again
                raise


def interop_status(gl_devices: list[int], device: int) -> tuple[bool, str]:
    """(usable, reason) of CUDA-GL interop for a renderer on CUDA `device` and a GL context on `gl_devices`: the
    same device, else the copy path (a texture of a context on another GPU cannot be written)."""
    if not gl_devices:
        return False, "the OpenGL context current here does not run on a CUDA device (no CUDA-GL interop)"
    if device not in gl_devices:
        return False, (
            f"the OpenGL context runs on CUDA device {', '.join(map(str, gl_devices))}, the cuda renderer "
            f"on device {device}: frames are copied"
        )
    return True, ""
