"""The backend contract: `Renderer`, the base every backend subclasses (its abstract methods, the default
`render_many`, the failure state), and `Capabilities`, the flags saying what a backend does beyond `upload` and
`render`. Sits above types (the settings and frames it speaks in); imports no backend."""

from __future__ import annotations

import abc
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import BackendFailed, RenderError
from ..model.camera import Camera, camera_key
from ..model.scene import Scene
from .types import Frame, RenderSettings


@dataclass(frozen=True)
class Capabilities:
    """What a backend does beyond `upload` and `render`, field by field: the app, video and bench ask these, never the
    backend's name. Each flag names the methods it promises.

    progressive: `partial` receives each tile as it is blended and `on_progress` counts tiles (else the whole frame
        arrives at the end, progress 0 then 1 of 1): worth showing while it refines.
    gl_texture: `render_to_texture(texture, camera, settings, cancel=, on_progress=) -> FrameStats` into a moderngl
        RGBA32F texture; `release_texture(glo)` before such a texture is deleted.
    gl_context: renders in an OpenGL context: the constructor takes `ctx=` (a moderngl context, current in the calling
        thread, which the renderer then belongs to); `check_context(ctx) -> (usable, why)` says whether one will do.
        Without it, `gl_interop() -> (usable, why)` says whether `render_to_texture` can write into the textures of the
        context current in this thread, and a renderer may be used from any thread, from several at once.
    shared_stage: renders of one camera share the per-camera stage (view-space positions and depth, 2D covariances
        before the mode's filter, SH colours, culling) across frames and settings while the scene is unchanged;
        `render_many` builds it once per distinct camera (progressive backends also blend its jobs' tiles
        interleaved); FrameStats.stage_reused and stage_ms say what was reused (the cpu also shares the depth order).
    trace: `trace(camera, settings, x, y) -> PixelTrace` (gbviewer.render.trace).
    simd: `FrameStats.simd` names the blend's SIMD path, switched process-wide by gbviewer.bench.simd.
    host: renders on the host's CPU cores (`RenderSettings.threads` of them): rates per core mean something.
    """

    progressive: bool = False
    gl_texture: bool = False
    gl_context: bool = False
    shared_stage: bool = False
    trace: bool = False
    simd: bool = False
    host: bool = False


class Renderer(abc.ABC):
    """What the app, video and bench see of a backend. A backend subclasses it, states its `capabilities` and
    is named once in `registry`."""

    name: ClassVar[str]
    capabilities: ClassVar[Capabilities] = Capabilities()
    _failure: str | None = None  # set by `failed`: why this renderer stopped working
    uploads: int = 0  # copies of scene data to the backend (splats, cells, a hierarchy, a cut's rows) since creation

    @classmethod
    @abc.abstractmethod
    def available(cls) -> tuple[bool, str]:
        """(usable on this machine, reason when not)."""

    @abc.abstractmethod
    def upload(self, scene: Scene) -> None:
        """Make `scene` the one later renders draw."""

    @abc.abstractmethod
    def render(
        self,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Callable[[int, int], None] | None = None,
        partial: np.ndarray | None = None,
    ) -> Frame:
        """The frame; once `cancel` is set it raises RenderCancelled within one tile batch (GPU backends: one
        dispatch); `on_progress(done, total)` is called from the render as tiles (or dispatches) finish; `partial`
        (float32 (height, width, 3)) receives finished tiles as they are blended (`capabilities.progressive`; else
        the whole frame at the end). A renderer that stopped working raises BackendFailed (see `failed`)."""

    @abc.abstractmethod
    def release(self) -> None:
        """Free what the renderer holds for its scene (buffers, device memory); `upload` again before the next
        render. Calling it twice is harmless."""

    def render_many(
        self,
        jobs: Sequence[tuple[Camera, RenderSettings]],
        *,
        cancel: Cancellable | None = None,
        on_progress: Callable[[int, int, int], None] | None = None,
        partials: Sequence[np.ndarray | None] | None = None,
    ) -> list[Frame]:
        """The frames of several (camera, settings) jobs, each what `render` gives it; `on_progress(job, done, total)`
        per job, `partials[job]` that job's partial frame (None: none); a cancel raises RenderCancelled and returns
        no frame. With `capabilities.shared_stage` the per-camera stage is built once per distinct camera and the jobs'
        tiles are blended interleaved (each job's first tiles arrive together); this default renders one job after
        another, the jobs of one camera (and sampling grid) together, so that a backend keeping its last stage
        (glsl, cuda) builds it once per distinct camera."""
        jobs = list(jobs)
        parts = job_partials(partials, len(jobs))
        first: dict[tuple, int] = {}
        order = sorted(
            range(len(jobs)), key=lambda i: first.setdefault((camera_key(jobs[i][0]), jobs[i][1].supersample), i)
        )
        frames: list[Frame | None] = [None] * len(jobs)
        for i in order:
            camera, settings = jobs[i]
            frames[i] = self.render(
                camera,
                settings,
                cancel=cancel,
                partial=parts[i],
                on_progress=None if on_progress is None else functools.partial(on_progress, i),
            )
        return frames  # type: ignore[return-value]

    def usable(self) -> tuple[bool, str]:
        """(whether this renderer still renders, why not): False once it raised BackendFailed."""
        return (False, self._failure) if self._failure is not None else (True, "")

    def failed(self, reason: str) -> BackendFailed:
        """Mark this renderer unusable for `reason` (a lost device, a failed launch); the error to raise."""
        self._failure = reason
        return BackendFailed(f"{self.name} backend stopped working: {reason}")

    @classmethod
    def gl_interop(cls) -> tuple[bool, str]:
        """With `capabilities.gl_texture` and without gl_context: whether `render_to_texture` can write into the
        textures of the OpenGL context current in this thread."""
        return False, f"the {cls.name} backend cannot write OpenGL textures"

    def release_texture(self, glo: int) -> None:  # noqa: B027 (a no-op unless the backend keeps something)
        """Forget what the renderer keeps for GL texture `glo` before the texture is deleted (nothing by default)."""


def job_partials(partials: Sequence[np.ndarray | None] | None, count: int) -> list[np.ndarray | None]:
    """`render_many`'s partials, one entry (or None) per job."""
    if partials is None:
        return [None] * count
    parts = list(partials)
    if len(parts) != count:
        raise RenderError(f"partials: expected one array or None per job ({count}), got {len(parts)}")
    return parts
