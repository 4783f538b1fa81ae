"""Render settings, frames, the `Renderer` protocol and its backends, and `render()`."""

from __future__ import annotations

import enum
import threading
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
    WSR = 4  # sort-free weighted sum (LC-WSR, Hou et al.): order independent, no sort
    DUPLEX = 5  # Duplex-GS: cells sorted, weighted sum inside a cell, cell transmittance and early termination

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

ORDER_INDEPENDENT = (Mode.WSR, Mode.DUPLEX)
DEFAULT_ET_GRADE = 4.0  # Duplex-GS ET_grade_final, the value training ends with (KERNELS.md §8.1)
DEFAULT_SIGMA = 10.0  # sort-free GS's initial sigma, for depth correction on scenes without a trained one
SORT_ENTRY_BYTES = 24  # per sorted key: 8-byte key + 4-byte value, input and output buffers (CUB SortPairs)


@dataclass(frozen=True)
class RenderSettings:
    """How to render: mode, N x N supersampling (1..8), background colour, SH degree cap, debug planes.

    `debug="window"` adds the final Gaussian Blending window size per pixel (H, W, 2) to `Frame.debug`.

    wsr and duplex: `depth_correct` multiplies each splat's weight by LC-WSR's max(0, 1 - z/sigma) (sigma: the
    scene's trained value, else 10); `et_grade` is Duplex-GS's E (None: the scene's trained value, else 4.0, the
    published final value); `cell_size` is the number of splats per cell built for scenes without cells.
    """

    mode: Mode = Mode.SCALAR
    supersample: int = 1
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int = 3
    debug: str = "none"
    threads: int = 0  # CPU threads, 0 = all
    depth_correct: bool = False
    et_grade: float | None = None
    cell_size: int = 5

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
        if self.et_grade is not None and not (np.isfinite(self.et_grade) and self.et_grade > 0):
            raise RenderError(f"et_grade must be a finite number > 0, got {self.et_grade!r}")
        if not (isinstance(self.cell_size, (int, np.integer)) and self.cell_size >= 1):
            raise RenderError(f"cell_size must be an integer >= 1, got {self.cell_size!r}")
        object.__setattr__(self, "depth_correct", bool(self.depth_correct))

    def label_for(self, scene: Scene) -> str:
        """The label with what the scene makes of the mode: wsr on a scene without trained view weights is an
        approximation (v = 1); duplex names where its cells come from."""
        label = self.label
        trained = scene.neural is not None or scene.meta.get("view_weights_in_opacity")
        if self.mode == Mode.WSR and scene.view_weight_sh is None and not trained:
            label += " (approx.: v=1)"
        elif self.mode == Mode.DUPLEX and scene.cells is None and scene.neural is None:
            label += f" (built cells, K={self.cell_size})"
        return label

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

    stats: preprocess_ms, sort_ms, blend_ms, total_ms, visible (splats that survive preprocess), sort_length
    (keys sorted by depth: tile-splat pairs; 0 for wsr, whose tile lists are only binned; tile-cell pairs for
    duplex), sort_bytes (sort_length x SORT_ENTRY_BYTES), pairs (tile-list entries blended), evaluations
    (splat-pixel evaluations), evals_per_pixel (mean), backend, mode (label_for the scene), simd (cpu backend:
    the SIMD path the blend ran, "scalar", "avx2" or "avx512", chosen by GBVIEWER_SIMD at load or
    gbviewer._native.set_simd); duplex adds cells, cells_visible and cell_misses (splat-tile pairs outside their
    cell's tiles); trained Duplex-GS models add decode_ms (the MLPs, per view).
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


def oit_params(scene: Scene, settings: RenderSettings) -> dict:
    """sigma, weight_background, et_grade, depth_correct for the native call.

    Trained values when the scene has them. Otherwise w_bg is chosen so that a lone faint splat of alpha a gets the
    coverage alpha blending gives it, to first order in a: wsr's a / (a + w_bg) needs w_bg = 1; duplex's
    (a/E) / (a/E + w_bg (1 - a/E)) needs w_bg = 1/E.
    """
    et = settings.et_grade if settings.et_grade is not None else (scene.et_grade or DEFAULT_ET_GRADE)
    wbg = scene.weight_background
    if wbg is None:
        wbg = 1.0 / et if settings.mode == Mode.DUPLEX else 1.0
    return {"sigma": scene.wsr_sigma or DEFAULT_SIGMA, "weight_background": float(wbg), "et_grade": float(et),
            "depth_correct": settings.depth_correct}


def view_scene(scene: Scene, camera: Camera) -> Scene:
    """The splats to render for this view: the scene itself, or a trained Duplex-GS model decoded for the camera."""
    return scene.neural.decode(camera) if scene.neural is not None else scene


def _native_extra(scene: Scene, settings: RenderSettings) -> dict:
    """Keyword arguments of the native render calls for wsr and duplex (view weights, cells, globals)."""
    if settings.mode not in ORDER_INDEPENDENT:
        return {}
    extra = dict(oit_params(scene, settings), weight_sh=scene.view_weight_sh)
    if settings.mode == Mode.DUPLEX:
        from .cells import cells_for

        cells = cells_for(scene, settings.cell_size)
        extra.update(cell_means=cells.means, cell_scales=cells.scales, cell_quats=cells.quats,
                     cell_offsets=cells.offsets, cell_members=cells.members)
    return extra


def _camera_args(camera: Camera) -> tuple:
    """Camera as the native modules take it: R (3x3), t, fx, fy, cx, cy, width, height, near."""
    return (np.ascontiguousarray(camera.R, np.float32), np.ascontiguousarray(camera.t, np.float32), camera.fx,
            camera.fy, camera.cx, camera.cy, camera.width, camera.height, camera.near)


def _frame(out: dict, camera: Camera, settings: RenderSettings, backend: str, t0: float,
           scene: Scene | None = None) -> Frame:
    """A Frame from a native module's result dict (rgb, alpha, evals, window?, per-stage ms and counts)."""
    stats = {k: out[k] for k in ("preprocess_ms", "sort_ms", "blend_ms", "visible", "sort_length", "evaluations")}
    stats.update(
        total_ms=(time.perf_counter() - t0) * 1e3,
        evals_per_pixel=out["evaluations"] / (camera.width * camera.height),
        backend=backend,
        mode=settings.label if scene is None else settings.label_for(scene),
    )
    stats.update(sort_stats(out, scene, settings))
    if "simd" in out:  # the CPU module: the SIMD path its blend ran ("scalar", "avx2" or "avx512")
        stats["simd"] = str(out["simd"])
    debug = {"evals": out["evals"]}
    if "window" in out:
        debug["window"] = out["window"]
    return Frame(out["rgb"], out["alpha"], stats, debug)


def sort_stats(out: dict, scene: Scene | None, settings: RenderSettings) -> dict:
    """pairs (tile-list entries blended), sort_bytes (sort_length keys of SORT_ENTRY_BYTES), and for duplex the
    visible cells, all cells and the splat-tile pairs outside their cell's rectangle (cell_misses)."""
    st = {"pairs": int(out["pairs"]), "sort_bytes": int(out["sort_length"]) * SORT_ENTRY_BYTES}
    if settings.mode == Mode.DUPLEX:
        st["cells_visible"] = int(out["cells_visible"])
        st["cell_misses"] = int(out["cell_misses"])
        if scene is not None:
            from .cells import cells_for

            st["cells"] = cells_for(scene, settings.cell_size).num_cells
    return st


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
            if "GBVIEWER_SIMD" in str(exc):  # the environment forces a SIMD path this CPU or build lacks
                return False, str(exc)
            return False, f"native module not built ({exc}); reinstall with pip install ."
        return True, ""

    def upload(self, scene: Scene) -> None:
        if scene is not self._scene:
            self._native.release_buffers()  # the per-frame buffers the native module keeps for the last scene
        self._scene = scene

    def render(self, camera: Camera, settings: RenderSettings) -> Frame:
        scene = self._scene
        if scene is None:
            raise RenderError("cpu renderer: upload(scene) before render()")
        t0 = time.perf_counter()
        scene = view_scene(scene, camera)
        decode_ms = (time.perf_counter() - t0) * 1e3
        out = self._native.render(
            scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d,
            *_camera_args(camera), int(settings.mode), settings.supersample, settings.sh_degree,
            np.asarray(settings.background, np.float32), settings.debug == "window", settings.threads,
            **_native_extra(scene, settings),
        )
        frame = _frame(out, camera, settings, self.name, t0, scene)
        if self._scene.neural is not None:
            frame.stats["decode_ms"] = decode_ms
        return frame


class CudaRenderer:
    """Native CUDA backend (gbviewer._native_cuda, built when a CUDA toolkit is present): the scene stays on the
    device; `render_to_texture` fills an OpenGL texture without a round trip through host memory.

    Threads may share one renderer: uploads and renders are serialised (a lock here around the scene and cells on
    the device, and a mutex in the native renderer around its buffers)."""

    name = "cuda"

    def __init__(self, device: int = -1) -> None:
        ok, why = self.available()
        if not ok:
            raise BackendUnavailable(f"cuda backend unavailable: {why}")
        from . import _native_cuda

        self._native = _native_cuda
        self._lock = threading.Lock()
        self._scene: Scene | None = None
        self._uploaded: Scene | None = None
        self._cells = None
        try:
            self._impl = _native_cuda.Renderer(device)
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
        with self._lock:
            self._scene = scene
            self._uploaded = None
            self._cells = None
            if scene.neural is None:
                self._upload(scene)

    def _upload(self, scene: Scene) -> None:
        # Forget what is on the device first: a failed upload (out of device memory) leaves no scene there.
        self._uploaded = None
        self._cells = None
        try:
            self._impl.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d)
            if scene.view_weight_sh is not None:
                self._impl.upload_weights(np.ascontiguousarray(scene.view_weight_sh, np.float32))
        except RuntimeError as exc:
            raise RenderError(f"cuda: {exc}") from None
        self._uploaded = scene

    def _prepare(self, camera: Camera, settings: RenderSettings) -> tuple[Scene, tuple]:
        """The view's scene on the device (trained Duplex-GS models: decoded and uploaded per frame), its cells for
        duplex, and the globals of wsr / duplex as positional arguments. Called with the lock held."""
        if self._scene is None:
            raise RenderError("cuda renderer: upload(scene) before render()")
        scene = view_scene(self._scene, camera)
        if scene is not self._uploaded:
            self._upload(scene)
        p = oit_params(scene, settings)
        if settings.mode == Mode.DUPLEX:
            from .cells import cells_for

            cells = cells_for(scene, settings.cell_size)
            if cells is not self._cells:
                cell_of = np.full(scene.num_splats, -1, np.int32)
                cell_of[cells.members] = np.repeat(np.arange(cells.num_cells, dtype=np.int32), cells.sizes)
                self._cells = None
                try:
                    self._impl.upload_cells(cells.means, cells.scales, cells.quats, cells.offsets, cells.members,
                                            cell_of)
                except RuntimeError as exc:
                    raise RenderError(f"cuda: {exc}") from None
                self._cells = cells
        return scene, (p["sigma"], p["weight_background"], p["et_grade"], p["depth_correct"])

    def render(self, camera: Camera, settings: RenderSettings) -> Frame:
        t0 = time.perf_counter()
        with self._lock:
            scene, oit = self._prepare(camera, settings)
            try:
                out = self._impl.render(*_camera_args(camera), int(settings.mode), settings.supersample,
                                        settings.sh_degree, np.asarray(settings.background, np.float32),
                                        settings.debug == "window", *oit)
            except RuntimeError as exc:
                raise RenderError(f"cuda: {exc}") from None
        return _frame(out, camera, settings, self.name, t0, scene)

    @property
    def device(self) -> int:
        """The CUDA device that holds the scene."""
        return self._impl.device

    def render_to_texture(self, texture_id: int, camera: Camera, settings: RenderSettings) -> None:
        """Render into an existing GL_RGBA32F texture of the camera's size; its GL context must be current.

        The first call with a texture registers it with CUDA and the registration is kept: call
        `release_texture(texture_id)` before deleting the texture (GL reuses texture names). When the GL context
        runs on another CUDA device than the renderer, the renderer moves to that device (the scene is uploaded
        again) so that the copy stays on one GPU."""
        with self._lock:
            devices = self._native.gl_devices()
            if devices and self._impl.device not in devices:
                try:
                    impl = self._native.Renderer(devices[0])
                except RuntimeError as exc:
                    raise RenderError(f"cuda: the GL context's device {devices[0]}: {exc}") from None
                self._impl, self._uploaded, self._cells = impl, None, None
            _, oit = self._prepare(camera, settings)
            try:
                self._impl.render_to_gl_texture(texture_id, *_camera_args(camera), int(settings.mode),
                                                settings.supersample, settings.sh_degree,
                                                np.asarray(settings.background, np.float32), *oit)
            except RuntimeError as exc:
                raise RenderError(f"cuda: {exc}") from None

    def release_texture(self, texture_id: int) -> None:
        """Drop a texture's CUDA registration (before deleting the texture; its GL context must be current)."""
        with self._lock:
            try:
                self._impl.release_gl_texture(texture_id)
            except RuntimeError as exc:
                raise RenderError(f"cuda: {exc}") from None


BACKENDS: dict[str, type] = {"cpu": CpuRenderer, "cuda": CudaRenderer}

_renderers: dict[str, tuple[Renderer, "weakref.ref[Scene]"]] = {}
_renderers_lock = threading.Lock()


def get_renderer(scene: Scene, backend: str = "cpu") -> Renderer:
    """The process's renderer of `backend` with `scene` uploaded. One renderer per backend, uploading only when the
    scene changes: it keeps the last scene alive, never every scene it has seen."""
    if backend not in BACKENDS:
        raise RenderError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    with _renderers_lock:
        entry = _renderers.get(backend)
        renderer = entry[0] if entry is not None else BACKENDS[backend]()
        if entry is None or entry[1]() is not scene:
            renderer.upload(scene)
            _renderers[backend] = (renderer, weakref.ref(scene))
        return renderer


def render(
    scene: Scene,
    camera: Camera,
    mode: str | Mode = "scalar",
    supersample: int = 1,
    backend: str = "cpu",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    sh_degree: int = 3,
    debug: str = "none",
    **options,
) -> Frame:
    """Render `scene` from `camera` in `mode` on `backend`; `options`: depth_correct, et_grade, cell_size, threads."""
    settings = RenderSettings(Mode.parse(mode), supersample, tuple(background), sh_degree, debug, **options)
    return get_renderer(scene, backend).render(camera, settings)


from .glsl import GlslRenderer  # noqa: E402 - glsl.py imports Frame, Mode, RenderSettings from this module

BACKENDS["glsl"] = GlslRenderer
