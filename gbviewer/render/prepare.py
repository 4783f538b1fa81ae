"""The per-frame preparation every backend shares: the view's splats (a trained Duplex-GS model decoded for the
camera), the level-of-detail cut, the wsr / duplex globals and cells, the camera as the native modules take it, and the
frame's stats."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ..core.errors import GBViewerError, RenderCancelled, RenderError
from ..lod import Hierarchy, check_plain, cut_rows, cut_scene, cut_view, hierarchy_for
from ..model.camera import Camera
from ..model.cells import Cells, cells_for
from ..model.scene import Scene
from .budget import check_frame_memory
from .modes import ORDER_INDEPENDENT
from .types import DEFAULT_ET_GRADE, DEFAULT_SIGMA, SORT_ENTRY_BYTES, Frame, FrameStats, Mode, RenderSettings


class OitParams(NamedTuple):
    """The globals of wsr and duplex, in the order the native renderers take them (gbv::OitParams)."""

    sigma: float
    weight_background: float
    et_grade: float
    depth_correct: bool


def oit_params(scene: Scene, settings: RenderSettings) -> OitParams:
    """sigma, weight_background, et_grade, depth_correct for the native call.

    Trained values when the scene has them. Otherwise w_bg is chosen so that a lone faint splat of alpha a gets the
    coverage alpha blending gives it, to first order in a: wsr's a / (a + w_bg) needs w_bg = 1; duplex's
    (a/E) / (a/E + w_bg (1 - a/E)) needs w_bg = 1/E.
    """
    oit = scene.oit
    trained_et = oit.et_grade if oit is not None else None
    et = settings.et_grade if settings.et_grade is not None else (trained_et or DEFAULT_ET_GRADE)
    wbg = oit.weight_background if oit is not None else None
    if wbg is None:
        wbg = 1.0 / et if settings.mode == Mode.DUPLEX else 1.0
    sigma = (oit.sigma if oit is not None else None) or DEFAULT_SIGMA
    return OitParams(sigma, float(wbg), float(et), settings.depth_correct)


def view_scene(scene: Scene, camera: Camera) -> Scene:
    """The splats to render for this view: the scene itself, or a trained Duplex-GS model decoded for the camera."""
    neural = scene.oit.neural if scene.oit is not None else None
    return neural.decode(camera) if neural is not None else scene


@dataclass(frozen=True, eq=False)
class Prepared:
    """What a backend renders this frame: the view's splats, the decode time (trained Duplex-GS models, else None),
    the wsr / duplex globals (None in the other modes), the duplex cells (None in the other modes), and for a
    level-of-detail frame drawn in place the scene's hierarchy and the native cut arguments (`cut_view`)."""

    scene: Scene
    decode_ms: float | None
    oit: OitParams | None
    cells: Cells | None
    tree: Hierarchy | None = None
    lod: tuple | None = None


MAX_SAMPLES = 2**31 - 1  # sub-samples of one frame: the native modules and shaders index them with int32


def prepare(
    scene: Scene | None,
    camera: Camera,
    settings: RenderSettings,
    backend: str,
    lod_in_place: bool = False,
    flag: np.ndarray | None = None,
    size: tuple[int, int] | None = None,
) -> Prepared:
    """The frame's inputs for `backend` from its uploaded scene (None: nothing uploaded, an error). A
    level-of-detail frame gets the cut's Scene, or with `lod_in_place` (every backend; not duplex or
    stochastic_popfree) the hierarchy and cut arguments to draw the same cut from the uploaded scene. `flag`: the
    render's cancel flag (RenderControl.flag), which stops the cut of a gathered cut Scene (RenderCancelled).
    `size`: the (width, height) of the part of the image rendered (the CPU renderer's regions), by default all of
    it."""
    if scene is None:
        raise RenderError(f"{backend} renderer: upload(scene) before render()")
    w, h = size or (camera.width, camera.height)
    samples = w * h * settings.supersample**2
    if samples > MAX_SAMPLES:
        raise RenderError(
            f"{w}x{h} at supersample {settings.supersample}: {samples} samples, "
            f"more than the {MAX_SAMPLES} one frame can hold"
        )
    check_frame_memory(camera, settings, scene.num_splats, size)
    t0 = time.perf_counter()
    view = view_scene(scene, camera)
    decode_ms = (time.perf_counter() - t0) * 1e3 if view is not scene else None
    tree = lod = None
    if settings.lod is not None:
        try:
            # duplex builds its cells of the cut's own splats; stochastic_popfree's depth plane reads the cut's
            if lod_in_place and settings.mode not in (Mode.DUPLEX, Mode.STOCHASTIC_POPFREE):
                check_plain(view)
                tree, lod = hierarchy_for(view), cut_view(camera, settings.lod)
            else:
                view = cut_scene(view, camera, settings.lod, threads=settings.threads, flag=flag)
        except RenderCancelled:
            raise
        except GBViewerError as exc:
            raise RenderError(str(exc)) from None
    oit = oit_params(view, settings) if settings.mode in ORDER_INDEPENDENT else None
    cells = cells_for(view, settings.cell_size) if settings.mode == Mode.DUPLEX else None
    return Prepared(view, decode_ms, oit, cells, tree, lod)


class CutRows:
    """The level-of-detail cut a GPU backend draws in place, kept between frames so that a still camera, and every
    pane of one camera, costs no cut and no upload: `rows` (int32, into the scene's rows followed by the hierarchy's
    interior nodes) and `weights` (float32 opacity multipliers) of the last cut, and `generation`, which counts the
    changes of rows or weights (what the device must receive again, and a stage built over them be rebuilt for)."""

    def __init__(self) -> None:
        self.key: tuple | None = None  # (tree, tau, band, eye bytes, focal, orthographic) of the kept cut
        self.rows: np.ndarray | None = None
        self.weights: np.ndarray | None = None
        self.generation = 0

    def forget(self) -> None:
        """Nothing kept: the next `update` counts as a change (a new tree went up, whose rows mean other nodes)."""
        self.key = self.rows = self.weights = None

    def update(self, tree: Hierarchy, view: tuple, threads: int = 0, flag: np.ndarray | None = None) -> bool:
        """Cut `tree` for `view` (`cut_view`'s tuple) unless it is the kept cut's; whether rows or weights changed."""
        tau, band, eye, focal, ortho = view
        key = (tree, tau, band, np.asarray(eye, np.float32).tobytes(), focal, ortho)
        if self.key is not None and key == self.key:
            return False
        self.key = None
        rows, weights = cut_rows(tree, view, threads, flag)
        changed = not (
            self.rows is not None and np.array_equal(rows, self.rows) and np.array_equal(weights, self.weights)
        )
        if changed:
            self.rows, self.weights = rows, weights
            self.generation += 1
        self.key = key
        return changed

    @property
    def count(self) -> int:
        return 0 if self.rows is None else len(self.rows)


class NativeUploads:
    """What the native renderers (CPU, CUDA) share: the scene, duplex cells and a level-of-detail hierarchy uploaded
    to `self._impl` once, and again only where the frame's differ (`uploads` counts them); `_native(method, *args)`
    calls it. Called with the renderer's lock held."""

    _uploaded: Scene | None = None
    _cells: Cells | None = None
    _tree: Hierarchy | None = None

    def _native(self, method: str, *args):
        return getattr(self._impl, method)(*args)

    def _send(self, method: str, *args) -> None:
        """An upload: `_native(method, *args)`, counted in `uploads` once done."""
        self._native(method, *args)
        self.uploads += 1

    def _upload(self, scene: Scene) -> None:
        """Forget what is uploaded first: a failed upload (out of memory) leaves no scene there."""
        self._uploaded = self._cells = self._tree = None
        self._send(
            "upload",
            scene.means,
            scene.scales,
            scene.quats,
            scene.opacities,
            np.ascontiguousarray(scene.sh, np.float32),
            scene.filter_3d,
        )  # float16 SH: a float32 copy
        if scene.oit is not None and scene.oit.view_weight_sh is not None:
            self._send("upload_weights", np.ascontiguousarray(scene.oit.view_weight_sh, np.float32))
        self._uploaded = scene

    def _upload_tree(self, t: Hierarchy, sh: np.ndarray) -> None:
        """The hierarchy as the CPU module walks it (`sh`: its SH as the scene's dtype gives them, float32): the
        interior nodes and what its cut reads."""
        self._send(
            "upload_lod", t.means, t.scales, t.quats, t.opacities, sh, t.filter_3d, t.radius, t.size, t.levels, t.order
        )

    def _sync(self, prep: Prepared) -> None:
        """Upload the view's splats, duplex cells and (a level-of-detail frame drawn in place) the scene's hierarchy
        where they are not yet."""
        scene, cells = prep.scene, prep.cells
        if scene is not self._uploaded or not scene.intact:  # maybe edited since: its stage too
            self._upload(scene)
        if prep.tree is not None and prep.tree is not self._tree:
            t = prep.tree
            sh = np.ascontiguousarray(t.sh.astype(scene.sh.dtype, copy=False), np.float32)  # float16 scene: so too
            try:
                self._upload_tree(t, sh)
            except ValueError as exc:  # a Scene made of values its renders drop (NaN): Scene.from_arrays drops them
                raise RenderError(
                    f"{scene.source}: level of detail: {exc} (the scene holds splats with non-finite "
                    "values or beyond float32; Scene.from_arrays drops those)"
                ) from None
            self._tree = t
        if cells is not None and cells is not self._cells:
            self._cells = None
            self._send(
                "upload_cells",
                cells.means,
                cells.scales,
                cells.quats,
                cells.offsets,
                cells.members,
                cells.cell_of(scene.num_splats),
            )
            self._cells = cells


def camera_args(camera: Camera) -> tuple:
    """Camera as the native modules take it: R (3x3), t, fx, fy, cx, cy, width, height, near, projection code."""
    return (
        np.ascontiguousarray(camera.R, np.float32),
        np.ascontiguousarray(camera.t, np.float32),
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        camera.width,
        camera.height,
        camera.near,
        camera.projection_code,
    )


def frame_stats(
    prep: Prepared,
    camera: Camera,
    settings: RenderSettings,
    backend: str,
    t0: float,
    *,
    preprocess_ms: float,
    sort_ms: float,
    blend_ms: float,
    visible: int,
    sort_length: int,
    pairs: int,
    evaluations: int,
    cells_visible: int | None = None,
    cell_misses: int | None = None,
    simd: str | None = None,
    stage_reused: bool | None = None,
    order_reused: bool | None = None,
    stage_ms: float | None = None,
    order_ms: float | None = None,
    lod_splats: int | None = None,
    fast: bool = False,
) -> FrameStats:
    """The frame's stats from a backend's counts and stage times; t0: when the render began; lod_splats: the
    level-of-detail cut a backend drew in place (else a cut's Scene says); fast: the backend ran the fast precision
    the settings ask for (a backend without that kernel renders, and says, exact)."""
    if settings.precision == "fast" and not fast:
        settings = replace(settings, precision="exact")
    counts = None  # the cut's (drawn, of)
    if settings.lod is not None:
        counts = prep.scene.meta.get("lod") if lod_splats is None else (lod_splats, prep.scene.num_splats)
        lod_splats = prep.scene.num_splats if counts is None else counts[0]
    return FrameStats(
        preprocess_ms=float(preprocess_ms),
        sort_ms=float(sort_ms),
        blend_ms=float(blend_ms),
        total_ms=(time.perf_counter() - t0) * 1e3,
        visible=int(visible),
        sort_length=int(sort_length),
        sort_bytes=int(sort_length) * SORT_ENTRY_BYTES,
        pairs=int(pairs),
        evaluations=int(evaluations),
        evals_per_pixel=int(evaluations) / (camera.width * camera.height),
        backend=backend,
        mode=settings.label_for(prep.scene, counts),
        simd=simd,
        precision=settings.precision,
        cells=prep.cells.num_cells if prep.cells is not None else None,
        cells_visible=None if cells_visible is None else int(cells_visible),
        cell_misses=None if cell_misses is None else int(cell_misses),
        decode_ms=prep.decode_ms,
        stage_reused=None if stage_reused is None else bool(stage_reused),
        order_reused=None if order_reused is None else bool(order_reused),
        stage_ms=None if stage_ms is None else float(stage_ms),
        order_ms=None if order_ms is None else float(order_ms),
        lod_splats=lod_splats,
    )


def native_stats(
    out: dict, prep: Prepared, camera: Camera, settings: RenderSettings, backend: str, t0: float
) -> FrameStats:
    """The stats of a native module's result dict (per-stage ms and counts, evaluations; duplex: cells_visible,
    cell_misses; the CPU module: simd, the SIMD path its blend ran, stage_reused, order_reused, stage_ms, order_ms
    and lod_splats)."""
    duplex = settings.mode == Mode.DUPLEX
    return frame_stats(
        prep,
        camera,
        settings,
        backend,
        t0,
        preprocess_ms=out["preprocess_ms"],
        sort_ms=out["sort_ms"],
        blend_ms=out["blend_ms"],
        visible=out["visible"],
        sort_length=out["sort_length"],
        pairs=out["pairs"],
        evaluations=out["evaluations"],
        cells_visible=out["cells_visible"] if duplex else None,
        cell_misses=out["cell_misses"] if duplex else None,
        simd=str(out["simd"]) if "simd" in out else None,
        stage_reused=out.get("stage_reused"),
        order_reused=out.get("order_reused"),
        stage_ms=out.get("stage_ms"),
        order_ms=out.get("order_ms"),
        lod_splats=out.get("lod_splats"),
        fast=bool(out.get("fast", False)),
    )


def native_frame(
    out: dict,
    prep: Prepared,
    camera: Camera,
    settings: RenderSettings,
    backend: str,
    t0: float,
    region: tuple[int, int, int, int] | None = None,
) -> Frame:
    """A Frame from a native module's result dict: rgb, alpha, evals, window? and `native_stats`' fields (of the
    region's pixels when only a region (x, y, w, h) was rendered)."""
    debug = {"evals": out["evals"]}
    if "window" in out:
        debug["window"] = out["window"]
    stats = native_stats(out, prep, camera, settings, backend, t0)
    if region is not None:
        stats = replace(stats, evals_per_pixel=stats.evaluations / (region[2] * region[3]))
    return Frame(out["rgb"], out["alpha"], stats, debug)


def check_display_texture(texture, camera: Camera, backend: str) -> None:
    """Refuse a `render_to_texture` target the frame does not fit: a moderngl RGBA32F texture of the camera's size."""
    size = getattr(texture, "size", None)
    kind = (getattr(texture, "components", None), getattr(texture, "dtype", None))
    if size != (camera.width, camera.height) or kind != (4, "f4"):
        raise RenderError(
            f"{backend} render_to_texture: expected an RGBA32F (4 components, 'f4') texture of "
            f"{camera.width}x{camera.height}, got {size} with components/dtype {kind}"
        )
