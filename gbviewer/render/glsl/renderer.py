"""The GLSL compute renderer: the CPU renderer's pipeline in OpenGL 4.3 compute shaders, through moderngl.

Every stage runs on the GPU (shaders/*.comp; the math is shaders/*.glsl, a port of native/include/gbv/*.h with the
same function names and constants):

1. stage.comp: the per-camera stage (`stage_splat`: view-space position and depth, 3D filter, 2D covariance before the
   mode's filter, screen position, SH colour, near and on-screen cull) of every splat, kept in the `stage` buffer
   while the scene, the camera, the SH degree and the on-screen cull's reach hold (`stage.Stage`: a mode, supersample
   or rate switch of one camera reuses it, as on the CPU); then preprocess.comp: the mode's `finish_splat` per splat
   -> Splat2D, tile rectangle, survivor flag; atomics count the tile-splat pairs and the depth range.
2. scan of the flags, compact.comp: survivors in splat-index order, key = depth bits - min depth bits.
3. radix sort (radix_count + scan + radix_scatter, 4-bit digits, stable) of the survivors by depth: order (depth,
   index). Sorting the per-splat depth once and then the pairs by tile is the LSD radix sort of the (tile, depth)
   keys with its low (depth) digits done before duplication, where they are the same for all of a splat's pairs.
4. gather_counts + scan + duplicate.comp: one (tile, splat) pair per touched tile, in depth order (one invocation
   per pair, which finds its splat by binary search).
5. radix sort of the pairs by tile (stable): every tile's list is ordered by (depth, splat index), the same order
   as the CPU driver's tile lists, which it bins in one global depth order (docs/modes.md#order).
6. tile_ranges.comp, then blend.comp: one work group per 16x16 output block; supersampling blends the N x N
   render tiles of the block and box-averages them in shared memory; gaussian_blending's fast precision is a variant
   of its own (`blend_defines`).

wsr skips the depth sort of step 3: its tile lists are binned by a radix sort of the tile alone and stay in
splat-index order (stats sort_length 0, as on the CPU), and blend.comp sums the weights in float. duplex replaces
steps 3-5 with cells.comp (each cell's visible splats, its screen proxy), a depth sort of the visible cells,
(tile, cell) pairs sorted by tile, and expand.comp / expand_ranges.comp, which turn every tile's cells into the
list of their splats; blend.comp reads each splat's cell from the scene's cell buffer.

Drivers that cap the loop iterations of one invocation (Mesa's llvmpipe) get the blend split into several dispatches:
see `limits`. Buffers, programs and dispatch are `gpu.Gpu`; the camera's uniforms and the stage of step 1 are in
`stage`, the scan, radix sort and pair sort in `sort`, the tile lists of steps 3-5 in `binning`, the blend of step 6
in `blend`. Counter slots, record sizes and the `oit` uniform's layout are the shaders' own (shaders/interface.glsl,
read by `interface`).

The scene is uploaded once (`upload`), a level-of-detail cut's hierarchy after it and the cut's rows as they change
(`lod`); per frame the camera goes up as uniforms, the counter buffer comes back (visible splats, pairs and depth
range: they size the pair buffers and the number of radix passes; with a loop cap also the longest tile list), and
`render` reads the image back; `render_to_texture` leaves it in a texture of the caller's (the viewer draws it from
there). Buffers grow (by 1.5x) when a frame needs more and are reused otherwise; `allocations` counts
(re)allocations, `uploads` the data written from the host.

Contexts: by default a headless EGL context shared by every renderer of the process
(`moderngl.create_context(standalone=True, backend="egl")`); or pass the app's `moderngl.Context`.
"""

from __future__ import annotations

import time

import numpy as np

from ...core.cancel import Cancellable
from ...core.errors import BackendUnavailable, RenderError
from ...model.camera import Camera
from ...model.cells import Cells
from ...model.scene import Scene
from ..contract import Capabilities, Renderer
from ..control import Progress, RenderControl
from ..modes import PER_PIXEL_SORTED
from ..prepare import Prepared, check_display_texture, frame_stats, prepare
from ..types import Frame, FrameStats, Mode, RenderSettings
from . import interface as gi
from .binning import bin_duplex, bin_splats, read_totals
from .blend import blend, planes
from .context import check_context, standalone_context
from .gpu import WG, Gpu
from .limits import blend_plan
from .lod import GpuCut
from .sort import SCAN_BLOCK, scan
from .stage import Stage, camera_uniforms

NO_OIT = gi.oit_uniform(0.0, 0.0, 1.0, False)  # the shaders' oit uniform outside wsr and duplex
WORD, VEC4 = gi.WORD_BYTES, gi.VEC4_BYTES


class GlslRenderer(Renderer):
    """OpenGL 4.3 compute-shader renderer; see the module docstring.

    `ctx`: a moderngl.Context to render in (the app's window context), or None for the shared headless EGL context.
    `precise_math`: use the shaders' ~1-ulp expf/logf instead of GLSL exp()/log() (whose accuracy is up to the
    driver; the built-ins are faster on GPUs with hardware exp2/log2).
    """

    name = "glsl"
    capabilities = Capabilities(gl_texture=True, gl_context=True, shared_stage=True)

    def __init__(self, ctx=None, precise_math: bool = True) -> None:
        self._owns_ctx = ctx is None
        self.ctx = standalone_context() if ctx is None else ctx
        check_context(self.ctx)
        self.gpu = Gpu(self.ctx, precise_math)
        self._scene: Scene | None = None
        self._uploaded: Scene | None = None
        self._n = 0
        self._sh_k = 1
        self._weight_k = 0
        self._cells: Cells | None = None
        self._lod = GpuCut()  # a level-of-detail cut drawn in place: its hierarchy and rows on the GPU
        self._generation = 0  # of the splats on the GPU: every upload starts a new one
        self._stage = Stage(self.gpu)  # the per-camera stage and what it holds

    @property
    def allocations(self) -> int:
        """Buffer and texture (re)allocations since creation."""
        return self.gpu.allocations

    uploads = property(lambda self: self.gpu.uploads, doc="Data writes from the host since creation (Gpu.uploads).")

    # ---- protocol ------------------------------------------------------------------------------------------------

    @classmethod
    def available(cls) -> tuple[bool, str]:
        """Whether the headless context (created here on first use, current in this thread) has OpenGL 4.3."""
        try:
            check_context(standalone_context())
        except BackendUnavailable as exc:
            return False, str(exc)
        return True, ""

    @classmethod
    def check_context(cls, ctx) -> tuple[bool, str]:
        """(usable, reason) for an app's own context. Unlike available(), this creates no headless context (which
        would become current in the calling thread)."""
        try:
            check_context(ctx)
        except BackendUnavailable as exc:
            return False, str(exc)
        return True, ""

    @classmethod
    def describe(cls) -> str:
        """GL renderer and version of the headless context (for benchmark reports:
        gbviewer.bench.machine_description)."""
        try:
            ctx = standalone_context()
        except BackendUnavailable as exc:
            return str(exc)
        return f"{ctx.info.get('GL_RENDERER', '?')}; OpenGL {ctx.info.get('GL_VERSION', '?')}"

    def _make_current(self) -> None:
        """Make the headless context this renderer owns current before it works: another one (an app window's,
        say) may have become current in this thread since. It stays current afterwards, as after its creation
        (leaving a `with ctx:` block would leave no context current: glcontext's EGL exit does not restore the
        previous one). A context the app passed in is the app's to keep current."""
        if self._owns_ctx:
            self.ctx.__enter__()

    def upload(self, scene: Scene) -> None:
        """Copy the scene to the GPU once (geometry 48 B and SH 12K B per splat); reuses buffers that are big enough.
        A trained Duplex-GS model is decoded per view instead, and its splats go up with every frame."""
        self._make_current()
        self._scene = scene
        self._uploaded = None
        self._cells = None
        if scene.oit is None or scene.oit.neural is None:
            self._upload_splats(scene)

    def _upload_splats(self, scene: Scene) -> None:
        self._uploaded = None  # nothing on the GPU is this scene's (or a stage of it) until every buffer is up
        self._stage.forget()
        self._lod.forget()
        n = scene.num_splats
        f3d = scene.filter_3d if scene.filter_3d is not None else np.zeros(n, np.float32)
        geom = gi.records(gi.GEOM_VEC4S, scene.means, scene.opacities, scene.scales, f3d, scene.quats)
        sh = np.ascontiguousarray(scene.sh, np.float32)
        self.gpu.upload("geom", geom, f"scene {scene.source}: splat geometry")
        self.gpu.upload("sh", sh, f"scene {scene.source}: SH coefficients")
        weight_sh = scene.oit.view_weight_sh if scene.oit is not None else None
        self._weight_k = 0 if weight_sh is None else int(weight_sh.shape[1])
        if self._weight_k:
            self.gpu.upload(
                "weight_sh", np.ascontiguousarray(weight_sh, np.float32), f"scene {scene.source}: view-weight SH"
            )
        self._n = n
        self._sh_k = int(scene.sh.shape[1])
        self._cells = None
        self._uploaded = scene
        self._generation += 1

    def _upload_cells(self, cells: Cells, n: int) -> None:
        """Cell ellipsoids (48 B per cell), member lists and each splat's cell (duplex)."""
        pad = np.zeros(cells.num_cells, np.float32)
        geom = gi.records(gi.CELL_GEOM_VEC4S, cells.means, pad, cells.scales, pad, cells.quats)
        self.gpu.upload("cell_geom", geom, "cell ellipsoids")
        self.gpu.upload("cell_offsets", cells.offsets, "cell offsets")
        self.gpu.upload("cell_members", cells.members, "cell members")
        self.gpu.upload("cell_of", cells.cell_of(n), "splat cells")
        self._cells = cells

    def _sync(self, prep: Prepared, settings: RenderSettings, flag: np.ndarray) -> None:
        """Put the view's splats (a trained Duplex-GS model's, every frame), duplex cells and a level-of-detail cut
        drawn in place (`lod`) on the GPU."""
        if prep.scene is not self._uploaded or not prep.scene.intact:  # maybe edited since: its stage too
            self._upload_splats(prep.scene)
        if prep.cells is not None and prep.cells is not self._cells:
            self._upload_cells(prep.cells, prep.scene.num_splats)
        if prep.tree is not None:
            self._lod.sync(self.gpu, prep, settings.threads, flag)

    def render(
        self,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Progress | None = None,
        partial: np.ndarray | None = None,
    ) -> Frame:
        control = RenderControl(cancel, on_progress, partial)
        control.check_partial(camera.width, camera.height)
        want_window = settings.debug == "window" and settings.mode == Mode.GAUSSIAN_BLENDING
        prep, counts, t0 = self._run(camera, settings, control, want_window)
        W, H = camera.width, camera.height
        img = np.frombuffer(self.gpu.texture.read(), np.float32).reshape(H, W, 4)
        evals = np.frombuffer(self.gpu.buffers["evals"].read(size=W * H * WORD), np.int32).reshape(H, W).copy()
        debug = {"evals": evals}
        if want_window:
            window = self.gpu.buffers["window"].read(size=W * H * gi.WINDOW_WORDS * WORD)
            debug["window"] = np.frombuffer(window, np.float32).reshape(H, W, gi.WINDOW_WORDS).copy()
        stats = frame_stats(prep, camera, settings, self.name, t0, evaluations=int(evals.sum(dtype=np.int64)), **counts)
        control.fill_partial(img[:, :, :3])
        return Frame(img[:, :, :3].copy(), img[:, :, 3].copy(), stats, debug)

    def render_to_texture(
        self,
        texture,
        camera: Camera,
        settings: RenderSettings,
        *,
        cancel: Cancellable | None = None,
        on_progress: Progress | None = None,
    ) -> FrameStats:
        """Render into `texture` (a moderngl RGBA32F texture of the camera's size, of this renderer's context or
        one sharing objects with it): rgb and alpha as `render`'s Frame, row 0 the image's top. The pixels stay on
        the GPU; what comes back is the stats (the evaluation counts summed per 1024 pixels on the GPU, 1/1024 of
        the image). No debug planes. The GL work is finished when it returns (another context may sample the
        texture once it binds it)."""
        check_display_texture(texture, camera, self.name)
        prep, counts, t0 = self._run(camera, settings, RenderControl(cancel, on_progress), False, texture)
        evaluations = self._sum_evals(camera.width * camera.height)
        return frame_stats(prep, camera, settings, self.name, t0, evaluations=evaluations, **counts)

    def _run(
        self, camera: Camera, settings: RenderSettings, control: RenderControl, want_window: bool, target=None
    ) -> tuple[Prepared, dict, float]:
        """One frame into `target` (None: the renderer's own output texture); its inputs, counts and start time."""
        self._make_current()
        t0 = time.perf_counter()
        prep = prepare(self._scene, camera, settings, self.name, lod_in_place=True, flag=control.flag)
        self._sync(prep, settings, control.flag)
        with control:
            counts = self._frame(camera, settings, prep, want_window, control, target)
        return prep, counts, t0

    def _sum_evals(self, n: int) -> int:
        """The sum of the frame's evaluation counts: scan_blocks.comp's per-block totals (it scans the counts in
        place: the evals buffer holds prefix sums afterwards), added up here in 64 bits."""
        blocks = -(-n // SCAN_BLOCK)
        sums = self.gpu.ensure("evals_sums", blocks * WORD, "evaluation sums")
        self.gpu.run(
            "scan_blocks.comp",
            blocks,
            (self.gpu.buffers["evals"], sums, self.gpu.buffers["totals"]),
            n=n,
            num_blocks=blocks,
            total_slot=gi.NO_TOTAL,
        )
        return int(np.frombuffer(sums.read(size=blocks * WORD), np.uint32).sum(dtype=np.int64))

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # noqa: BLE001 - context already gone (interpreter exit)
            pass

    def release(self) -> None:
        """Free the GPU buffers and the output texture (also done when the renderer is garbage-collected)."""
        self.gpu.release()
        self._scene = self._uploaded = None
        self._cells = None
        self._lod.forget()
        self._stage.forget()

    # ---- pipeline ------------------------------------------------------------------------------------------------

    def _frame(
        self,
        camera: Camera,
        settings: RenderSettings,
        prep: Prepared,
        want_window: bool,
        control: RenderControl,
        target=None,
    ) -> dict:
        """Preprocess, bin and sort, blend into `target` or the output texture (`control` checked between the stages
        and the blend's dispatches); returns the stage times and counts."""
        gpu = self.gpu
        mode = settings.mode
        oit = NO_OIT if prep.oit is None else gi.oit_uniform(*prep.oit[:3], prep.oit.depth_correct)
        in_place = prep.tree is not None  # a level-of-detail cut: splat i is row lod_rows[i] (lod_rows.glsl)
        n, N = self._lod.cut.count if in_place else self._n, settings.supersample
        max_deg = {1: 0, 4: 1, 9: 2, 16: 3}[self._sh_k]
        sh_deg = max(0, min(settings.sh_degree, max_deg))

        t0 = time.perf_counter()
        # per-scene buffers (sized by the splat count; allocated on the first frame, grown with the scene)
        splats = gpu.ensure("splats", n * gi.SPLAT_VEC4S * VEC4, "preprocessed splats")
        rects = gpu.ensure("rects", n * gi.RECT_WORDS * WORD, "tile rectangles")
        flags = gpu.ensure("flags", n * WORD, "survivor flags")
        dkeys = [gpu.ensure(f"depth_keys{i}", n * WORD, "depth keys") for i in (0, 1)]
        dvals = [gpu.ensure(f"depth_vals{i}", n * WORD, "depth order") for i in (0, 1)]
        gpu.ensure("pair_counts", n * WORD, "pair counts")  # read by bin_splats
        totals = gpu.ensure("totals", gi.TOTALS_BYTES)
        totals.write(gi.totals_init().tobytes())

        cam_uniforms = camera_uniforms(camera, N)
        (RW, RH), (gx, gy) = cam_uniforms["cam_size"], cam_uniforms["grid"]
        num_tiles = gx * gy
        weight = gpu.buffers["weight_sh"] if self._weight_k else gpu.ensure("dummy", VEC4)
        lod = dict(lod_in_place=int(in_place))
        rows = gpu.buffers["lod_rows"] if in_place else gpu.ensure("dummy", VEC4)
        generations = (self._generation, self._lod.cut.generation if in_place else None)
        stage, stage_reused, stage_ms = self._stage.build(
            settings, n, self._sh_k, sh_deg, cam_uniforms, rows, lod, generations
        )
        rays = gpu.ensure("rays", n * gi.RAY_VEC4S * VEC4, "ray data") if mode in PER_PIXEL_SORTED else None
        gpu.run(
            "preprocess.comp",
            -(-n // WG),
            (
                gpu.buffers["geom"],
                gpu.buffers["sh"],
                splats,
                rects,
                flags,
                totals,
                weight,
                stage,
                planes(gpu, settings, n),
                rays or gpu.ensure("dummy", VEC4),
                rows,
            ),
            num_splats=n,
            sh_k=self._sh_k,
            sh_deg=sh_deg,
            mode=int(mode),
            weight_k=self._weight_k,
            oit=oit,
            view_filter=gi.view_filter_uniform(*settings.view_filter.native()[:4]),
            view_rules=gi.view_rules_uniform(*settings.view_filter.native()[4:]),
            **lod,
            **cam_uniforms,
        )
        scan(gpu, flags, n, total_slot=gi.TOTAL_VISIBLE)
        gpu.run("compact.comp", -(-n // WG), (splats, rects, flags, totals, dkeys[0], dvals[0]), num_splats=n)
        t = read_totals(gpu)
        slots = (gi.TOTAL_VISIBLE, gi.TOTAL_PAIRS, gi.TOTAL_DEPTH_MIN, gi.TOTAL_DEPTH_MAX, gi.TOTAL_OVERFLOW)
        visible, pairs, dmin, dmax, overflow = (int(t[i]) for i in slots)
        t1 = time.perf_counter()

        if overflow:
            raise RenderError(f"glsl backend: more than 2^32 tile-splat pairs at {RW}x{RH}; render a smaller image")
        counts = {}
        if mode == Mode.DUPLEX:
            tvals, ranges, sort_length, pairs, counts["cells_visible"] = bin_duplex(
                gpu, prep.cells, cam_uniforms, num_tiles
            )
        else:
            resort = mode == Mode.STOPTHEPOP and settings.queue > 0
            tvals, ranges = bin_splats(
                gpu, mode, visible, pairs, dmin, dmax, num_tiles, gx, cam_uniforms["cam_f"] if resort else None
            )
            sort_length = 0 if mode == Mode.WSR else pairs
        queue = (0 if mode == Mode.EVAL3D else settings.queue) if mode in PER_PIXEL_SORTED else None
        plan, longest = blend_plan(gpu, N, ranges, num_tiles, pairs, queue)
        self.ctx.finish()
        t2 = time.perf_counter()
        control.check()
        blend(gpu, camera, settings, want_window, plan, longest, splats, tvals, ranges, rays, oit, control, target)
        self.ctx.finish()
        return dict(
            preprocess_ms=(t1 - t0) * 1e3,
            sort_ms=(t2 - t1) * 1e3,
            blend_ms=(time.perf_counter() - t2) * 1e3,
            visible=visible,
            sort_length=sort_length,
            pairs=pairs,
            stage_reused=stage_reused,
            stage_ms=stage_ms,
            lod_splats=n if in_place else None,
            fast=settings.precision == "fast",
            **counts,
        )
