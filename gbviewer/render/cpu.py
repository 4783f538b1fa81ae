"""The CPU backend: the native C++/OpenMP renderer gbviewer._native.Renderer (built from native/cpu)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import BackendUnavailable, RenderError
from ..model.camera import Camera
from ..model.cells import Cells
from ..model.scene import Scene
from .contract import Capabilities, Renderer, job_partials
from .control import FrameLock, Progress, RenderControl
from .prepare import NativeUploads, OitParams, Prepared, camera_args, native_frame, prepare
from .trace import PixelTrace, from_native
from .types import DEFAULT_ET_GRADE, DEFAULT_SIGMA, Frame, Mode, RenderSettings

NO_OIT = OitParams(DEFAULT_SIGMA, 1.0, DEFAULT_ET_GRADE, False)  # the native defaults, unused outside wsr and duplex
Region = tuple[int, int, int, int]  # x, y, w, h of the output pixels a frame renders
REGION_ALIGN = 16  # a region's x and y times the supersampling: multiples of the native tile (gbv::TILE)
Job = tuple[Camera, RenderSettings]


def batches(jobs: list[Job], preps: list[Prepared]) -> list[range]:
    """Runs of consecutive jobs one native call renders: the same view splats (a trained Duplex-GS model's views
    differ per camera), no two different cells, the same thread count."""
    out: list[range] = []
    start, cells = 0, None
    for i, prep in enumerate(preps):
        other_cells = prep.cells is not None and cells is not None and prep.cells is not cells
        if i > start and (
            prep.scene is not preps[start].scene or jobs[i][1].threads != jobs[start][1].threads or other_cells
        ):
            out.append(range(start, i))
            start, cells = i, None
        cells = prep.cells if prep.cells is not None else cells
    return out + [range(start, len(jobs))] if jobs else out


class CpuRenderer(NativeUploads, Renderer):
    """Native C++/OpenMP backend: the scene is uploaded once (the native renderer references its arrays); a trained
    Duplex-GS model's view is uploaded per frame, duplex cells when they change.

    Threads may share one renderer: frames are serialised (a lock here around the uploaded scene and cells, and a
    mutex in the native renderer around its buffers); each frame runs on every core."""

    name = "cpu"
    capabilities = Capabilities(progressive=True, shared_stage=True, trace=True, simd=True, host=True)

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
        return (
            *camera_args(camera),
            settings.native_mode,
            settings.supersample,
            settings.sh_degree,
            np.asarray(settings.background, np.float32),
        )

    def render(
        self,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Progress | None = None,
        partial: np.ndarray | None = None,
    ) -> Frame:
        progress = None if on_progress is None else (lambda _job, done, total: on_progress(done, total))
        return self.render_many([(camera, settings)], cancel=cancel, on_progress=progress, partials=[partial])[0]

    def render_region(
        self, camera: Camera, settings: RenderSettings, region: Region, *, cancel: Cancellable | None = None
    ) -> Frame:
        """The part region = (x, y, w, h) (output pixels) of the frame `render` makes, bit for bit: the camera, its
        culling, level-of-detail cut and tile grid stay the whole image's, only the buffers shrink to the part. x
        and y times the supersampling must be multiples of REGION_ALIGN (whole tiles); not duplex (its cells cull
        by the whole image's tiles). Its stats count the part's pixels. A bad region: a one-line RenderError."""
        x, y, w, h = map(int, region)
        n = settings.supersample
        if settings.mode == Mode.DUPLEX:
            raise RenderError("render_region: duplex renders whole images only (its cells cull by the image's tiles)")
        if not (0 <= x <= camera.width - w and 0 <= y <= camera.height - h and w >= 1 and h >= 1):
            raise RenderError(
                f"render_region: region {region} must be (x, y, w, h) inside the {camera.width}x{camera.height} image"
            )
        if x * n % REGION_ALIGN or y * n % REGION_ALIGN:
            raise RenderError(
                f"render_region: region {region}: x and y times supersample {n} must be multiples of {REGION_ALIGN}"
            )
        return self.render_many([(camera, settings)], cancel=cancel, regions=[region])[0]

    def render_many(
        self,
        jobs: Sequence[Job],
        *,
        cancel: Cancellable | None = None,
        on_progress: Callable[[int, int, int], None] | None = None,
        partials: Sequence[np.ndarray | None] | None = None,
        regions: Sequence[Region | None] | None = None,
    ) -> list[Frame]:
        """`Renderer.render_many` in as few native calls as `batches` allows: in each, the per-camera stage once per
        distinct camera (or reused from the last call) and every job's tiles blended in one interleaved loop.
        regions: per job, None or the part it renders (`render_region`)."""
        t0 = time.perf_counter()
        jobs = list(jobs)
        regions = (
            [None if r is None else tuple(map(int, r)) for r in regions] if regions is not None else [None] * len(jobs)
        )
        parts = job_partials(partials, len(jobs))
        for (camera, _), part in zip(jobs, parts):
            RenderControl(partial=part).check_partial(camera.width, camera.height)
        control = RenderControl(cancel, on_progress)
        control.check()  # before any work (a trained model's decode included)
        frames: list[Frame] = []
        with self._lock:
            preps = [
                prepare(
                    self._scene,
                    camera,
                    settings,
                    self.name,
                    lod_in_place=True,
                    flag=control.flag,
                    size=None if r is None else r[2:],
                )
                for (camera, settings), r in zip(jobs, regions)
            ]
            for run in batches(jobs, preps):
                for prep in [
                    next((p for p in preps[run.start : run.stop] if p.cells is not None), preps[run.start]),
                    *(p for p in preps[run.start : run.stop] if p.tree is not None),
                ]:
                    self._sync(prep)
                hook = control.hook
                outs = self._impl.render_many(
                    [
                        (
                            *self._frame_args(camera, settings),
                            settings.debug == "window",
                            *(preps[i].oit or NO_OIT),
                            settings.view_filter.native(),
                            preps[i].lod,
                            settings.seed,
                            settings.frame,
                            settings.precision == "fast",
                            regions[i],
                        )
                        for i, (camera, settings) in zip(run, jobs[run.start : run.stop])
                    ],
                    threads=jobs[run.start][1].threads,
                    cancel=control.flag,
                    on_progress=None
                    if hook is None
                    else (lambda job, done, total, b=run.start, h=hook: h(b + job, done, total)),
                    partials=parts[run.start : run.stop],
                )
                # the native render skipped its remaining work once it saw the flag (even if cleared since)
                control.check(any(out["cancelled"] for out in outs))
                frames += [
                    native_frame(out, preps[i], *jobs[i], self.name, t0, regions[i]) for i, out in zip(run, outs)
                ]
        return frames

    def trace(self, camera: Camera, settings: RenderSettings, x: int, y: int) -> PixelTrace:
        """The pixel trace of (x, y) in this frame (gbviewer.render.trace; `trace_pixel` checks the pixel)."""
        with self._lock:
            prep = prepare(self._scene, camera, settings, self.name, lod_in_place=True)
            self._sync(prep)
            out = self._impl.trace(
                *self._frame_args(camera, settings),
                *(prep.oit or ()),
                x=x,
                y=y,
                view_filter=settings.view_filter.native(),
                lod=prep.lod,
                seed=settings.seed,
                frame=settings.frame,
                fast=settings.precision == "fast",
            )
        return from_native(out, settings, camera, x, y, prep.scene.num_splats)
