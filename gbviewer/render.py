"""Render settings, frames, the `Renderer` protocol and its backends, and `render()`."""

from __future__ import annotations

import enum
import time
import weakref
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .camera import Camera
from .errors import BackendUnavailable, RenderError
from .scene import Scene


class Mode(enum.IntEnum):
    """Blending modes; values match `gbv::Mode` in native/include/gbv/common.h."""

    SCALAR = 0  # 3DGS: alpha at the pixel centre, +0.3 px^2 dilation
    MIP = 1  # Mip-Splatting 2D filter (0.1 px^2 with opacity compensation)
    ANALYTIC = 2  # Analytic-Splatting: alpha integrated over the pixel, scalar transmittance
    GAUSSIAN_BLENDING = 3  # spatial transmittance window (Gaussian Blending)

    @classmethod
    def parse(cls, value: "str | int | Mode") -> "Mode":
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            try:
                return cls[value.strip().upper().replace("-", "_")]
            except KeyError:
                names = ", ".join(m.name.lower() for m in cls)
                raise RenderError(f"unknown mode {value!r}; expected one of {names}") from None
        try:
            return cls(int(value))
        except ValueError:
            raise RenderError(f"unknown mode {value!r}") from None

    @property
    def label(self) -> str:
        return self.name.lower()


DEBUG_OUTPUTS = ("none", "window")


@dataclass(frozen=True)
class RenderSettings:
    """How to render: mode, N x N supersampling (1..8), background colour, SH degree cap, debug planes.

    `debug="window"` adds the final Gaussian Blending window size per pixel (H, W, 2) to `Frame.debug`.
    """

    mode: Mode = Mode.SCALAR
    supersample: int = 1
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int = 3
    debug: str = "none"
    threads: int = 0  # CPU threads, 0 = all

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode.parse(self.mode))
        if not (isinstance(self.supersample, (int, np.integer)) and 1 <= self.supersample <= 8):
            raise RenderError(f"supersample must be an integer 1..8, got {self.supersample!r}")
        bg = tuple(float(v) for v in self.background)
        if len(bg) != 3 or not all(np.isfinite(bg)):
            raise RenderError(f"background must be three finite numbers, got {self.background!r}")
        object.__setattr__(self, "background", bg)
        if self.debug not in DEBUG_OUTPUTS:
            raise RenderError(f"debug output {self.debug!r}; expected one of {DEBUG_OUTPUTS}")

    @property
    def label(self) -> str:
        return self.mode.label + (f" {self.supersample}x{self.supersample}" if self.supersample > 1 else "")

    @property
    def spec(self) -> str:
        """The inverse of `parse`: 'gaussian_blending', 'scalar:3', ..."""
        return self.mode.label + (f":{self.supersample}" if self.supersample > 1 else "")

    @classmethod
    def parse(cls, spec: str, **kwargs) -> "RenderSettings":
        """'MODE' or 'MODE:N' (N x N supersampling); 'supersample:N' means scalar with N x N samples."""
        name, _, n = spec.strip().partition(":")
        try:
            supersample = int(n) if n else 1
        except ValueError:
            raise RenderError(f"mode {spec!r}: supersampling factor {n!r} is not an integer") from None
        mode = Mode.SCALAR if name.strip().lower() == "supersample" else Mode.parse(name)
        return cls(mode, supersample, **kwargs)

    @classmethod
    def parse_list(cls, specs: str, **kwargs) -> "list[RenderSettings]":
        """Comma-separated mode specs, e.g. 'scalar,supersample:3,gaussian_blending'."""
        out = [cls.parse(s, **kwargs) for s in specs.split(",") if s.strip()]
        if not out:
            raise RenderError("no modes given")
        return out


@dataclass
class Frame:
    """A rendered image: rgb (H,W,3) float32, alpha = 1 - final transmittance (H,W), debug planes, stats.

    stats: preprocess_ms, sort_ms, blend_ms, total_ms, visible (splats), sort_length (tile-splat pairs),
    evaluations (splat-pixel evaluations), evals_per_pixel (mean), backend, mode.
    debug: "evals" (H,W) splats evaluated per output pixel (summed over sub-samples); "window" (H,W,2)
    when requested.
    """

    rgb: np.ndarray
    alpha: np.ndarray
    stats: dict = field(default_factory=dict)
    debug: dict = field(default_factory=dict)

    @property
    def transmittance(self) -> np.ndarray:
        return 1.0 - self.alpha


class Renderer(Protocol):
    """What the app, video and bench see of a backend."""

    name: str

    @classmethod
    def available(cls) -> tuple[bool, str]:
        """(usable, reason when not)."""

    def upload(self, scene: Scene) -> None: ...

    def render(self, camera: Camera, settings: RenderSettings) -> Frame: ...


def _camera_args(camera: Camera) -> tuple:
    """Camera as the native modules take it: R (3x3), t, fx, fy, cx, cy, width, height, near."""
    return (np.ascontiguousarray(camera.R, np.float32), np.ascontiguousarray(camera.t, np.float32), camera.fx,
            camera.fy, camera.cx, camera.cy, camera.width, camera.height, camera.near)


def _frame(out: dict, camera: Camera, settings: RenderSettings, backend: str, t0: float) -> Frame:
    """A Frame from a native module's result dict (rgb, alpha, evals, window?, per-stage ms and counts)."""
    stats = {k: out[k] for k in ("preprocess_ms", "sort_ms", "blend_ms", "visible", "sort_length", "evaluations")}
    stats.update(
        total_ms=(time.perf_counter() - t0) * 1e3,
        evals_per_pixel=out["evaluations"] / (camera.width * camera.height),
        backend=backend,
        mode=settings.label,
    )
    debug = {"evals": out["evals"]}
    if "window" in out:
        debug["window"] = out["window"]
    return Frame(out["rgb"], out["alpha"], stats, debug)


class CpuRenderer:
    """Native C++/OpenMP backend (gbviewer._native)."""

    name = "cpu"

    def __init__(self) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cpu backend unavailable: {why}")
        from . import _native

        self._native = _native
        self._scene: Scene | None = None

    @classmethod
    def available(cls) -> tuple[bool, str]:
        try:
            from . import _native  # noqa: F401
        except ImportError as exc:
            return False, f"native module not built ({exc}); reinstall with pip install ."
        return True, ""

    def upload(self, scene: Scene) -> None:
        self._scene = scene

    def render(self, camera: Camera, settings: RenderSettings) -> Frame:
        scene = self._scene
        if scene is None:
            raise RenderError("cpu renderer: upload(scene) before render()")
        t0 = time.perf_counter()
        out = self._native.render(
            scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d,
            *_camera_args(camera), int(settings.mode), settings.supersample, settings.sh_degree,
            np.asarray(settings.background, np.float32), settings.debug == "window", settings.threads,
        )
        return _frame(out, camera, settings, self.name, t0)


class CudaRenderer:
    """Native CUDA backend (gbviewer._native_cuda, built when a CUDA toolkit is present): the scene stays on the
    device; `render_to_texture` fills an OpenGL texture without a round trip through host memory."""

    name = "cuda"

    def __init__(self) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cuda backend unavailable: {why}")
        from . import _native_cuda

        try:
            self._impl = _native_cuda.Renderer()
        except RuntimeError as exc:
            raise BackendUnavailable(f"cuda backend unavailable: {exc}") from None

    @classmethod
    def available(cls) -> tuple[bool, str]:
        try:
            from . import _native_cuda
        except ImportError:
            return False, "not built: no CUDA toolkit (nvcc) was found when gbviewer was installed"
        ok, why = _native_cuda.availability()
        return ok, "" if ok else why

    def upload(self, scene: Scene) -> None:
        try:
            self._impl.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d)
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None

    def render(self, camera: Camera, settings: RenderSettings) -> Frame:
        t0 = time.perf_counter()
        try:
            out = self._impl.render(*_camera_args(camera), int(settings.mode), settings.supersample,
                                    settings.sh_degree, np.asarray(settings.background, np.float32),
                                    settings.debug == "window")
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None
        return _frame(out, camera, settings, self.name, t0)

    def render_to_texture(self, texture_id: int, camera: Camera, settings: RenderSettings) -> None:
        """Render into an existing GL_RGBA32F texture of the camera's size (its GL context must be current)."""
        try:
            self._impl.render_to_gl_texture(texture_id, *_camera_args(camera), int(settings.mode),
                                            settings.supersample, settings.sh_degree,
                                            np.asarray(settings.background, np.float32))
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None


BACKENDS: dict[str, type] = {"cpu": CpuRenderer, "cuda": CudaRenderer}

_renderers: "weakref.WeakKeyDictionary[Scene, dict[str, Renderer]]" = weakref.WeakKeyDictionary()


def get_renderer(scene: Scene, backend: str = "cpu") -> Renderer:
    """A renderer of `backend` with `scene` uploaded, cached per scene (uploads happen once)."""
    if backend not in BACKENDS:
        raise RenderError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    per_scene = _renderers.setdefault(scene, {})
    if backend not in per_scene:
        renderer = BACKENDS[backend]()
        renderer.upload(scene)
        per_scene[backend] = renderer
    return per_scene[backend]


def render(
    scene: Scene,
    camera: Camera,
    mode: str | Mode = "scalar",
    supersample: int = 1,
    backend: str = "cpu",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    sh_degree: int = 3,
    debug: str = "none",
) -> Frame:
    """Render `scene` from `camera` in `mode` on `backend`."""
    settings = RenderSettings(Mode.parse(mode), supersample, tuple(background), sh_degree, debug)
    return get_renderer(scene, backend).render(camera, settings)


from .glsl import GlslRenderer  # noqa: E402 - glsl.py imports Frame, Mode, RenderSettings from this module

BACKENDS["glsl"] = GlslRenderer
