"""GLSL compute backend: the CPU renderer's pipeline in OpenGL 4.3 compute shaders, through moderngl.

Every stage runs on the GPU (shaders/*.comp; the math is shaders/*.glsl, a port of native/include/gbv/*.h with the
same function names and constants):

1. preprocess.comp: `preprocess_splat` per splat -> Splat2D, tile rectangle, survivor flag; atomics count the
   tile-splat pairs and the depth range.
2. scan of the flags, compact.comp: survivors in splat-index order, key = depth bits - min depth bits.
3. radix sort (radix_count + scan + radix_scatter, 4-bit digits, stable) of the survivors by depth: order (depth,
   index). Sorting the per-splat depth once and then the pairs by tile is the LSD radix sort of the (tile, depth)
   keys with its low (depth) digits done before duplication, where they are the same for all of a splat's pairs.
4. gather_counts + scan + duplicate.comp: one (tile, splat) pair per touched tile, in depth order (one invocation
   per pair, which finds its splat by binary search).
5. radix sort of the pairs by tile (stable): every tile's list is ordered by (depth, splat index), exactly as the
   CPU driver's per-tile std::sort of (depth bits, index) keys.
6. tile_ranges.comp, then blend.comp: one work group per 16x16 output block; supersampling blends the N x N
   render tiles of the block and box-averages them in shared memory.

wsr skips the depth sort of step 3: its tile lists are binned by a radix sort of the tile alone and stay in
splat-index order (stats sort_length 0, as on the CPU), and blend.comp sums the weights in float. duplex replaces
steps 3-5 with cells.comp (each cell's visible splats, its screen proxy), a depth sort of the visible cells,
(tile, cell) pairs sorted by tile, and expand.comp / expand_ranges.comp, which turn every tile's cells into the
list of their splats; blend.comp reads each splat's cell from the scene's cell buffer.

Drivers may cap the loop iterations of one invocation: Mesa's llvmpipe ends every loop of an invocation once it has
run 65535 iterations in total, silently, so a 100k-splat tile list would be cut short. `loop_limit()` measures the
cap once per context; when a frame's longest tile list does not fit under it, blend.comp runs as several
dispatches (groups of render tiles, windows of the lists) that keep the per-pixel state in a buffer in between.

The scene is uploaded once (`upload`); per frame the camera goes up as uniforms, 20 bytes of counters come back
(visible splats, pairs and depth range: they size the pair buffers and the number of radix passes; 4 more with a
loop cap: the longest tile list), and
`render` reads the image back while `render_texture` leaves it in an RGBA32F texture for the app to draw. Buffers
grow (by 1.5x) when a frame needs more and are reused otherwise; `allocations` counts (re)allocations.

Contexts: by default a headless EGL context shared by every renderer of the process
(`moderngl.create_context(standalone=True, backend="egl")`); or pass the app's `moderngl.Context`.
"""

from __future__ import annotations

import re
import sys
import time
import weakref
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import BackendUnavailable, RenderError
from .render import Frame, Mode, RenderSettings
from .scene import Scene

GL_REQUIRED = 430
SHADER_DIR = Path(__file__).parent / "shaders"
if not SHADER_DIR.is_dir():  # running from a source checkout: shaders/ is at the repository top
    SHADER_DIR = Path(__file__).resolve().parents[1] / "shaders"

WG = 256  # work-group size of the 1D kernels
SCAN_BLOCK = 1024  # elements per scan_blocks group
RADIX_BLOCK = 2048  # keys per radix group (256 threads x 8)
RADIX_BITS = 4
MAX_GROUPS = 65535
GROWTH = 1.5

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)


def shader_source(name: str, defines: dict[str, object] | None = None) -> str:
    """The GLSL 4.30 source of shaders/`name` with its #include "file" lines expanded (each file once)."""
    seen: set[str] = set()

    def expand(fname: str) -> str:
        if fname in seen:
            return ""
        seen.add(fname)
        path = SHADER_DIR / fname
        try:
            text = path.read_text()
        except OSError as exc:
            raise BackendUnavailable(f"glsl backend: shader {path} not found ({exc}); reinstall gbviewer") from None
        return _INCLUDE.sub(lambda m: expand(m.group(1)), text)

    head = "#version 430\n" + "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return head + expand(name)


# ---- contexts ---------------------------------------------------------------------------------------------------

_standalone: dict[str, object] = {}


def _create_standalone():
    import moderngl

    kwargs = {"standalone": True, "require": GL_REQUIRED}
    if sys.platform.startswith("linux"):
        kwargs["backend"] = "egl"
    return moderngl.create_context(**kwargs)


def standalone_context():
    """The process-wide headless context (created on first use); raises BackendUnavailable with the reason."""
    if "ctx" not in _standalone and "error" not in _standalone:
        try:
            import moderngl  # noqa: F401
        except ImportError as exc:
            _standalone["error"] = f"moderngl is not installed ({exc}); pip install 'moderngl>=5.8'"
        else:
            try:
                ctx = _create_standalone()
            except Exception as exc:  # noqa: BLE001 - glcontext raises plain Exceptions with the driver's message
                msg = str(exc).strip() or type(exc).__name__
                _standalone["error"] = (
                    f"no OpenGL {GL_REQUIRED // 100}.{GL_REQUIRED % 100 // 10} context: {msg} (headless Linux needs "
                    "EGL and Mesa: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)"
                )
            else:
                _standalone["ctx"] = ctx
    if "ctx" in _standalone:
        return _standalone["ctx"]
    raise BackendUnavailable(f"glsl backend unavailable: {_standalone['error']}")


def _check_context(ctx) -> None:
    if ctx.version_code < GL_REQUIRED:
        raise BackendUnavailable(
            f"glsl backend unavailable: the context is OpenGL {ctx.version_code / 100:.1f} "
            f"({ctx.info.get('GL_RENDERER', '?')}); compute shaders need OpenGL 4.3"
        )


_program_cache: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_loop_limits: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
LOOP_PROBE = 1 << 20


def loop_limit(ctx) -> int | None:
    """Loop iterations one invocation may run on this context (None: no cap up to 2^20), measured once."""
    if ctx not in _loop_limits:
        prog = ctx.compute_shader(shader_source("loop_probe.comp"))
        buf = ctx.buffer(reserve=4)
        buf.bind_to_storage_buffer(0)
        prog["n"].value = LOOP_PROBE
        prog.run(1, 1, 1)
        ctx.memory_barrier()
        count = int(np.frombuffer(buf.read(), np.uint32)[0])
        buf.release()
        prog.release()
        _loop_limits[ctx] = None if count >= LOOP_PROBE else count
    return _loop_limits[ctx]


def plan_blend(supersample: int, longest: int, limit: int | None) -> list[tuple[int, int, int, int]]:
    """Blend dispatches as (subtile_begin, subtile_end, chunk_begin, chunk_end), each within `limit` loop iterations
    per invocation. A render tile costs one iteration per splat plus two per batch of 256 and a few for the tile;
    the box sum costs N^2 in all; 1024 iterations are kept in reserve."""
    tiles = supersample * supersample
    big = 2**31 - 1
    if limit is None:
        return [(0, tiles, 0, big)]
    budget = limit - 2 * tiles - 1024

    def cost(n: int) -> int:
        return n + 2 * -(-n // 256) + 4

    if cost(longest) <= budget:
        group = max(1, min(tiles, budget // cost(longest)))
        return [(t, min(t + group, tiles), 0, big) for t in range(0, tiles, group)]
    chunk = 256
    while cost(chunk + 256) <= budget:
        chunk += 256
    if cost(chunk) > budget:
        raise RenderError(f"glsl backend: the driver allows only {limit} loop iterations per invocation")
    return [(t, t + 1, c, c + chunk) for t in range(tiles) for c in range(0, longest, chunk)]


class GlslRenderer:
    """OpenGL 4.3 compute-shader renderer; see the module docstring.

    `ctx`: a moderngl.Context to render in (the app's window context), or None for the shared headless EGL context.
    `precise_math`: use the shaders' ~1-ulp expf/logf instead of GLSL exp()/log() (whose accuracy is up to the
    driver; the built-ins are faster on GPUs with hardware exp2/log2).
    """

    name = "glsl"

    def __init__(self, ctx=None, precise_math: bool = True) -> None:
        self._owns_ctx = ctx is None
        self.ctx = standalone_context() if ctx is None else ctx
        _check_context(self.ctx)
        self.precise_math = bool(precise_math)
        self.allocations = 0  # buffer and texture (re)allocations since creation
        self._buffers: dict[str, object] = {}
        self._texture = None
        self._scene: Scene | None = None
        self._n = 0
        self._sh_k = 1
        self._weight_k = 0
        self._cells = None
        self._view = None  # the decoded per-view scene last uploaded (trained Duplex-GS models)
        self.max_block = int(self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 1 << 27)
        self.last_stats: dict = {}

    # ---- protocol ------------------------------------------------------------------------------------------------

    @classmethod
    def available(cls) -> tuple[bool, str]:
        """Whether the headless context (created here on first use, current in this thread) has OpenGL 4.3."""
        try:
            _check_context(standalone_context())
        except BackendUnavailable as exc:
            return False, str(exc)
        return True, ""

    @classmethod
    def check_context(cls, ctx) -> tuple[bool, str]:
        """(usable, reason) for an app's own context. Unlike available(), this creates no headless context (which
        would become current in the calling thread)."""
        try:
            _check_context(ctx)
        except BackendUnavailable as exc:
            return False, str(exc)
        return True, ""

    @classmethod
    def describe(cls) -> str:
        """GL renderer and version of the headless context (for benchmark reports)."""
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
        self._cells = None
        self._view = None
        if scene.neural is None:
            self._upload_splats(scene)

    def _upload_splats(self, scene: Scene) -> None:
        n = scene.num_splats
        f3d = scene.filter_3d if scene.filter_3d is not None else np.zeros(n, np.float32)
        geom = np.empty((n, 12), np.float32)
        geom[:, 0:3] = scene.means
        geom[:, 3] = scene.opacities
        geom[:, 4:7] = scene.scales
        geom[:, 7] = f3d
        geom[:, 8:12] = scene.quats
        sh = np.ascontiguousarray(scene.sh, np.float32)
        self._upload("geom", geom, f"scene {scene.source}: splat geometry")
        self._upload("sh", sh, f"scene {scene.source}: SH coefficients")
        self._weight_k = 0 if scene.view_weight_sh is None else int(scene.view_weight_sh.shape[1])
        if self._weight_k:
            self._upload("weight_sh", np.ascontiguousarray(scene.view_weight_sh, np.float32),
                         f"scene {scene.source}: view-weight SH")
        self._n = n
        self._sh_k = int(scene.sh.shape[1])
        self._cells = None

    def _upload_cells(self, cells, n: int) -> None:
        """Cell ellipsoids (48 B per cell), member lists and each splat's cell (duplex)."""
        m = cells.num_cells
        geom = np.zeros((m, 12), np.float32)
        geom[:, 0:3] = cells.means
        geom[:, 4:7] = cells.scales
        geom[:, 8:12] = cells.quats
        cell_of = np.full(n, -1, np.int32)
        cell_of[cells.members] = np.repeat(np.arange(m, dtype=np.int32), cells.sizes)
        self._upload("cell_geom", geom, "cell ellipsoids")
        self._upload("cell_offsets", np.ascontiguousarray(cells.offsets, np.int32), "cell offsets")
        self._upload("cell_members", np.ascontiguousarray(cells.members, np.int32), "cell members")
        self._upload("cell_of", cell_of, "splat cells")
        self._cells = cells

    def render(self, camera: Camera, settings: RenderSettings) -> Frame:
        self._make_current()
        t0 = time.perf_counter()
        want_window = settings.debug == "window" and settings.mode == Mode.GAUSSIAN_BLENDING
        tex, stats = self._frame(camera, settings, want_window)
        W, H = camera.width, camera.height
        img = np.frombuffer(tex.read(), np.float32).reshape(H, W, 4)
        evals = np.frombuffer(self._buffers["evals"].read(size=W * H * 4), np.int32).reshape(H, W).copy()
        debug = {"evals": evals}
        if want_window:
            window = self._buffers["window"].read(size=W * H * 8)
            debug["window"] = np.frombuffer(window, np.float32).reshape(H, W, 2).copy()
        evaluations = int(evals.sum(dtype=np.int64))
        stats.update(
            evaluations=evaluations,
            evals_per_pixel=evaluations / (W * H),
            total_ms=(time.perf_counter() - t0) * 1e3,
        )
        self.last_stats = stats
        return Frame(img[:, :, :3].copy(), img[:, :, 3].copy(), stats, debug)

    def render_texture(self, camera: Camera, settings: RenderSettings):
        """Render into the renderer's RGBA32F texture (rgb, alpha) and return it without reading it back.

        Row 0 of the texture is the top image row (flip v when drawing). The texture is reused by the next frame of
        the same size. Stats (without `evaluations`) are in `last_stats`.
        """
        t0 = time.perf_counter()
        self._make_current()
        tex, stats = self._frame(camera, settings, False)
        stats["total_ms"] = (time.perf_counter() - t0) * 1e3
        self.last_stats = stats
        return tex

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # noqa: BLE001 - context already gone (interpreter exit)
            pass

    def release(self) -> None:
        """Free the GPU buffers and the output texture (also done when the renderer is garbage-collected)."""
        for buf in self._buffers.values():
            buf.release()
        self._buffers.clear()
        if self._texture is not None:
            self._texture.release()
            self._texture = None

    # ---- buffers -------------------------------------------------------------------------------------------------

    def _check_size(self, nbytes: int, what: str) -> None:
        if nbytes > self.max_block:
            raise RenderError(
                f"glsl backend: {what} needs {nbytes / 2**20:.0f} MiB in one storage buffer, more than this GPU's "
                f"limit of {self.max_block / 2**20:.0f} MiB (GL_MAX_SHADER_STORAGE_BLOCK_SIZE, "
                f"{self.ctx.info.get('GL_RENDERER', '?')}); render a smaller scene or image, or use backend='cpu'"
            )

    def _allocated(self, obj, what: str, nbytes: int):
        err = self.ctx.error
        if err == "GL_OUT_OF_MEMORY":
            obj.release()
            raise RenderError(f"glsl backend: out of GPU memory allocating {nbytes / 2**20:.0f} MiB for {what}")
        self.allocations += 1
        return obj

    def _ensure(self, name: str, nbytes: int, what: str = ""):
        """Buffer `name` with at least `nbytes` (grown by GROWTH, never shrunk)."""
        nbytes = max(int(nbytes), 16)
        buf = self._buffers.get(name)
        if buf is not None and buf.size >= nbytes:
            return buf
        what = what or name
        self._check_size(nbytes, what)
        size = nbytes if buf is None else min(max(nbytes, int(buf.size * GROWTH)), self.max_block)
        size = (size + 255) // 256 * 256
        if buf is not None:
            buf.release()
            del self._buffers[name]
        self.ctx.error  # noqa: B018 - clear a stale error flag before checking ours
        buf = self._allocated(self.ctx.buffer(reserve=size), what, size)
        self._buffers[name] = buf
        return buf

    def _upload(self, name: str, data: np.ndarray, what: str) -> None:
        buf = self._ensure(name, data.nbytes, what)
        buf.write(data.tobytes())

    def _ensure_texture(self, W: int, H: int):
        tex = self._texture
        if tex is not None and tex.size == (W, H):
            return tex
        if tex is not None:
            tex.release()
        self.ctx.error  # noqa: B018
        tex = self._allocated(self.ctx.texture((W, H), 4, dtype="f4"), "the output image", W * H * 16)
        import moderngl

        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._texture = tex
        return tex

    # ---- programs ------------------------------------------------------------------------------------------------

    def _program(self, name: str, **defines):
        defines.setdefault("GBV_PRECISE_MATH", int(self.precise_math))
        key = (name, tuple(sorted(defines.items())))
        cache = _program_cache.setdefault(self.ctx, {})
        prog = cache.get(key)
        if prog is None:
            src = shader_source(name, defines)
            try:
                prog = self.ctx.compute_shader(src)
            except Exception as exc:  # noqa: BLE001 - moderngl raises its Error with the compiler log
                raise BackendUnavailable(f"glsl backend: {name} does not compile on "
                                         f"{self.ctx.info.get('GL_RENDERER', '?')}: {exc}") from None
            cache[key] = prog
        return prog

    @staticmethod
    def _set(prog, **uniforms) -> None:
        for k, v in uniforms.items():
            u = prog.get(k, None)
            if u is None:
                continue  # optimised out
            if isinstance(v, np.ndarray):
                u.write(v.tobytes())
            else:
                u.value = v

    def _dispatch(self, prog, groups: int, *bindings) -> None:
        for i, buf in enumerate(bindings):
            buf.bind_to_storage_buffer(i)
        if groups <= 0:
            return
        gx = min(groups, MAX_GROUPS)
        prog.run(gx, -(-groups // gx), 1)
        self.ctx.memory_barrier()

    # ---- pipeline ------------------------------------------------------------------------------------------------

    def _scan(self, buf, n: int, total_slot: int = -1, level: int = 0) -> None:
        """Exclusive prefix sum of uint buf[0..n) in place; the total goes to totals[total_slot] when >= 0."""
        if n <= 0:
            return
        blocks = -(-n // SCAN_BLOCK)
        sums = self._ensure(f"scan_sums{level}", blocks * 4)
        prog = self._program("scan_blocks.comp")
        self._set(prog, n=n, num_blocks=blocks, total_slot=total_slot)
        self._dispatch(prog, blocks, buf, sums, self._ensure("totals", 64))
        if blocks > 1:
            self._scan(sums, blocks, total_slot, level + 1)
            add = self._program("scan_add.comp")
            self._set(add, n=n, num_blocks=blocks)
            self._dispatch(add, blocks, buf, sums)

    def _radix_sort(self, keys, vals, keys_tmp, vals_tmp, n: int, bits: int):
        """Stable LSD sort of (keys, vals)[0..n) by the low `bits` of the keys; returns the buffers holding it."""
        passes = -(-bits // RADIX_BITS)
        if n <= 1 or passes == 0:
            return keys, vals
        blocks = -(-n // RADIX_BLOCK)
        counts = self._ensure("radix_counts", 16 * blocks * 4)
        count, scatter = self._program("radix_count.comp"), self._program("radix_scatter.comp")
        for p in range(passes):
            shift = p * RADIX_BITS
            self._set(count, n=n, shift=shift, num_blocks=blocks)
            self._dispatch(count, blocks, keys, counts)
            self._scan(counts, 16 * blocks)
            self._set(scatter, n=n, shift=shift, num_blocks=blocks)
            self._dispatch(scatter, blocks, keys, vals, keys_tmp, vals_tmp, counts)
            keys, vals, keys_tmp, vals_tmp = keys_tmp, vals_tmp, keys, vals
        return keys, vals

    def _fill(self, buf, n: int, value: int) -> None:
        prog = self._program("fill.comp")
        self._set(prog, n=n, value=value)
        self._dispatch(prog, -(-n // WG), buf)

    def _frame(self, camera: Camera, settings: RenderSettings, want_window: bool):
        from .cells import cells_for
        from .render import SORT_ENTRY_BYTES, oit_params

        scene = self._scene
        if scene is None:
            raise RenderError("glsl renderer: upload(scene) before render()")
        t_decode = time.perf_counter()
        if scene.neural is not None:
            scene = scene.neural.decode(camera)
            self._upload_splats(scene)
        decode_ms = (time.perf_counter() - t_decode) * 1e3
        mode = settings.mode
        params = oit_params(scene, settings) if mode in (Mode.WSR, Mode.DUPLEX) else None
        oit = (0.0, 0.0, 1.0, 0.0) if params is None else (
            params["sigma"], params["weight_background"], params["et_grade"], float(params["depth_correct"]))
        cells = None
        if mode == Mode.DUPLEX:
            cells = cells_for(scene, settings.cell_size)
            if self._cells is not cells:
                self._upload_cells(cells, scene.num_splats)
        ctx = self.ctx
        n, N = self._n, settings.supersample
        W, H = camera.width, camera.height
        RW, RH = W * N, H * N
        gx, gy = -(-RW // 16), -(-RH // 16)
        num_tiles = gx * gy
        max_deg = {1: 0, 4: 1, 9: 2, 16: 3}[self._sh_k]
        sh_deg = max(0, min(settings.sh_degree, max_deg))
        f32 = np.float32
        Nf = f32(N)

        t0 = time.perf_counter()
        # per-scene buffers (sized by the splat count; allocated on the first frame, grown with the scene)
        splats = self._ensure("splats", n * 64, "preprocessed splats")
        rects = self._ensure("rects", n * 16, "tile rectangles")
        flags = self._ensure("flags", n * 4, "survivor flags")
        dkeys = [self._ensure(f"depth_keys{i}", n * 4, "depth keys") for i in (0, 1)]
        dvals = [self._ensure(f"depth_vals{i}", n * 4, "depth order") for i in (0, 1)]
        self._ensure("pair_counts", n * 4, "pair counts")  # read by _bin_splats
        totals = self._ensure("totals", 64)
        totals.write(np.array([0, 0, 0xFFFFFFFF, 0, 0, 0, 0, 0xFFFFFFFF, 0, 0, 0, 0, 0, 0, 0, 0],
                              np.uint32).tobytes())

        cam_uniforms = dict(
            grid=(gx, gy), cam_R=np.ascontiguousarray(camera.R, f32).reshape(9),
            cam_t=np.ascontiguousarray(camera.t, f32),
            cam_f=(float(f32(camera.fx) * Nf), float(f32(camera.fy) * Nf), float(f32(camera.cx) * Nf),
                   float(f32(camera.cy) * Nf)),
            cam_size=(RW, RH), cam_near=float(f32(camera.near)),
        )
        prog = self._program("preprocess.comp")
        self._set(prog, num_splats=n, sh_k=self._sh_k, sh_deg=sh_deg, mode=int(mode), weight_k=self._weight_k,
                  oit=oit, **cam_uniforms)
        weight = self._buffers["weight_sh"] if self._weight_k else self._ensure("dummy", 16)
        self._dispatch(prog, -(-n // WG), self._buffers["geom"], self._buffers["sh"], splats, rects, flags, totals,
                       weight)
        self._scan(flags, n, total_slot=0)
        prog = self._program("compact.comp")
        self._set(prog, num_splats=n)
        self._dispatch(prog, -(-n // WG), splats, rects, flags, totals, dkeys[0], dvals[0])
        visible, pairs, dmin, dmax, overflow = (int(v) for v in np.frombuffer(totals.read(size=20), np.uint32))
        t1 = time.perf_counter()

        if overflow:
            raise RenderError(f"glsl backend: more than 2^32 tile-splat pairs at {RW}x{RH}; render a smaller image")
        extra = {}
        if mode == Mode.DUPLEX:
            tvals, ranges, sort_length, pairs, _, extra = self._bin_duplex(cells, cam_uniforms, num_tiles)
        else:
            tvals, ranges = self._bin_splats(mode, visible, pairs, dmin, dmax, num_tiles, gx)
            sort_length = 0 if mode == Mode.WSR else pairs
        limit = loop_limit(ctx)
        longest = 0
        if limit is not None and pairs > 0:
            prog = self._program("list_max.comp")
            self._set(prog, n=num_tiles)
            self._dispatch(prog, -(-num_tiles // WG), ranges, totals)
            longest = int(np.frombuffer(totals.read(size=4, offset=20), np.uint32)[0])
        plan = plan_blend(N, longest, limit)
        ctx.finish()
        t2 = time.perf_counter()
        return self._blend(camera, settings, want_window, plan, longest, splats, tvals, ranges, oit, dict(
            preprocess_ms=(t1 - t0) * 1e3, sort_ms=(t2 - t1) * 1e3, visible=visible, sort_length=sort_length,
            pairs=pairs, sort_bytes=sort_length * SORT_ENTRY_BYTES, **extra,
            **({"decode_ms": decode_ms} if self._scene.neural is not None else {})), t2)

    def _bin_splats(self, mode: Mode, visible: int, pairs: int, dmin: int, dmax: int, num_tiles: int, gx: int):
        """Tile lists of splats: by (tile, depth, index), or for wsr by (tile, index) with no depth sort."""
        dkeys = [self._buffers[f"depth_keys{i}"] for i in (0, 1)]
        dvals = [self._buffers[f"depth_vals{i}"] for i in (0, 1)]
        ranges = self._ensure("ranges", num_tiles * 8, "tile ranges")
        self._fill(ranges, num_tiles * 2, 0)
        if visible == 0:
            return self._ensure("tile_vals0", pairs * 4, "tile-splat pairs"), ranges
        if mode == Mode.WSR:
            order = dvals[0]  # survivors in splat-index order: binning only
        else:
            _, order = self._radix_sort(dkeys[0], dvals[0], dkeys[1], dvals[1], visible, (dmax - dmin).bit_length())
        tvals = self._pairs_by_tile(order, self._buffers["rects"], self._buffers["pair_counts"], visible, pairs, gx,
                                    num_tiles, ranges, "tile-splat pairs")
        return tvals, ranges

    def _pairs_by_tile(self, order, rects, counts, n: int, pairs: int, gx: int, num_tiles: int, ranges, what: str):
        """One (tile, item) pair for every tile each of the n ordered items touches (`rects`), stably radix-sorted by
        tile, so every tile keeps the items' order; writes each tile's [start, end) into `ranges` and returns the
        items in tile order."""
        keys0, vals0, keys1, vals1 = (self._ensure(f"tile_{k}{i}", pairs * 4, what) for i in (0, 1)
                                      for k in ("keys", "vals"))
        prog = self._program("gather_counts.comp")
        self._set(prog, n=n)
        self._dispatch(prog, -(-n // WG), order, rects, counts)
        self._scan(counts, n)
        prog = self._program("duplicate.comp")
        self._set(prog, num_pairs=pairs, num_splats=n, grid_x=gx)
        self._dispatch(prog, -(-pairs // WG), order, rects, counts, keys0, vals0)
        tkeys, tvals = self._radix_sort(keys0, vals0, keys1, vals1, pairs, (num_tiles - 1).bit_length())
        prog = self._program("tile_ranges.comp")
        self._set(prog, n=pairs)
        self._dispatch(prog, -(-pairs // WG), tkeys, ranges)
        return tvals

    def _bin_duplex(self, cells, cam_uniforms: dict, num_tiles: int):
        """Duplex binning (KERNELS.md §8.3): project the cells with a visible splat, sort them by depth, one pair per
        (tile, cell), sort the pairs by tile, expand every pair to its cell's visible splats. Returns the splat list,
        the tile ranges in it, the tile-cell pairs (the sort length), the list length, the visible splats and the
        cell counts."""
        m = cells.num_cells
        gx = cam_uniforms["grid"][0]
        totals = self._buffers["totals"]
        cell_out = self._ensure("cell_out", m * 16, "projected cells")
        cell_rects = self._ensure("cell_rects", m * 16, "cell rectangles")
        cflags = self._ensure("cell_flags", m * 4, "cell flags")
        vis = self._ensure("cell_vis", len(cells.members) * 4, "visible cell members")
        prog = self._program("cells.comp")
        self._set(prog, num_cells=m, **cam_uniforms)
        self._dispatch(prog, -(-m // WG), self._buffers["cell_geom"], self._buffers["cell_offsets"],
                       self._buffers["cell_members"], self._buffers["rects"], vis, cell_out, cell_rects, cflags,
                       totals)
        self._scan(cflags, m, total_slot=9)
        t = np.frombuffer(totals.read(size=48), np.uint32)
        cell_pairs, cmin, cmax, ncells, visible = (int(t[i]) for i in (6, 7, 8, 9, 11))
        ckeys = [self._ensure(f"cell_keys{i}", m * 4, "cell keys") for i in (0, 1)]
        cvals = [self._ensure(f"cell_vals{i}", m * 4, "cell order") for i in (0, 1)]
        prog = self._program("cell_compact.comp")
        self._set(prog, num_cells=m)
        self._dispatch(prog, -(-m // WG), cell_out, cell_rects, cflags, totals, ckeys[0], cvals[0])
        cell_ranges = self._ensure("cell_ranges", num_tiles * 8, "tile ranges of cells")
        ranges = self._ensure("ranges", num_tiles * 8, "tile ranges")
        self._fill(ranges, num_tiles * 2, 0)
        self._fill(cell_ranges, num_tiles * 2, 0)
        expanded = 0
        tlist = self._ensure("expanded", 16)
        if ncells > 0 and cell_pairs > 0:
            _, order = self._radix_sort(ckeys[0], cvals[0], ckeys[1], cvals[1], ncells, (cmax - cmin).bit_length())
            counts = self._ensure("cell_pair_counts", ncells * 4, "cell tile counts")
            tvals = self._pairs_by_tile(order, cell_rects, counts, ncells, cell_pairs, gx, num_tiles, cell_ranges,
                                        "tile-cell pairs")
            offs = self._ensure("expand_offsets", cell_pairs * 4, "expanded list offsets")
            prog = self._program("expand.comp")
            self._set(prog, n=cell_pairs, mode=0)
            self._dispatch(prog, -(-cell_pairs // WG), tvals, cell_out, self._buffers["cell_offsets"], vis, offs,
                           tlist)
            self._scan(offs, cell_pairs, total_slot=10)
            expanded = int(np.frombuffer(totals.read(size=4, offset=40), np.uint32)[0])
            tlist = self._ensure("expanded", expanded * 4, "expanded tile lists")
            self._set(prog, n=cell_pairs, mode=1)
            self._dispatch(prog, -(-cell_pairs // WG), tvals, cell_out, self._buffers["cell_offsets"], vis, offs,
                           tlist)
            prog = self._program("expand_ranges.comp")
            self._set(prog, num_tiles=num_tiles, n=cell_pairs)
            self._dispatch(prog, -(-num_tiles // WG), cell_ranges, offs, totals, ranges)
        extra = {"cells_visible": ncells, "cells": m}
        return tlist, ranges, cell_pairs, expanded, visible, extra

    def _blend(self, camera: Camera, settings: RenderSettings, want_window: bool, plan, longest: int, splats, tvals,
               ranges, oit, stats: dict, t2: float):
        ctx = self.ctx
        N = settings.supersample
        W, H = camera.width, camera.height
        RW, RH = W * N, H * N
        gx, gy = -(-RW // 16), -(-RH // 16)
        tex = self._ensure_texture(W, H)
        evals = self._ensure("evals", W * H * 4, "evaluation counts")
        window = self._ensure("window", W * H * 8 if want_window else 16, "window sizes")
        bx, by = -(-W // 16), -(-H // 16)
        split = len(plan) > 1
        state = self._ensure("blend_state", bx * by * 256 * 48 if split else 16, "blend state")
        accum = self._ensure("blend_accum", bx * by * 256 * 32 if split else 16, "blend sums")
        prog = self._program("blend.comp", **{f"BLEND_MODE_{settings.mode.name}": 1, "SUPERSAMPLED": int(N > 1)})
        self._set(prog, out_size=(W, H), supersample=N, grid=(gx, gy), background=tuple(settings.background),
                  want_window=int(want_window), oit=oit)
        cell_of = self._buffers["cell_of"] if settings.mode == Mode.DUPLEX else self._ensure("dummy", 16)
        for i, buf in enumerate((splats, tvals, ranges, evals, window, state, accum, cell_of)):
            buf.bind_to_storage_buffer(i)
        tex.bind_to_image(0, read=False, write=True)
        tiles = N * N
        for sub0, sub1, c0, c1 in plan:
            self._set(prog, subtile_begin=sub0, subtile_end=sub1, chunk_begin=c0, chunk_end=c1,
                      load_state=int(c0 > 0), store_state=int(c1 < longest), load_accum=int(sub0 > 0),
                      store_accum=int(sub1 < tiles))
            prog.run(bx, by, 1)
            ctx.memory_barrier()
        ctx.finish()
        t3 = time.perf_counter()

        stats.update(blend_ms=(t3 - t2) * 1e3, backend=self.name, mode=settings.label_for(self._scene))
        return tex, stats
