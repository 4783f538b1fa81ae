"""blend.comp's dispatch in the glsl backend: the defines of the shader variant a frame needs (`blend_defines`),
stochastic_popfree's depth planes (`planes`) and the blend of a frame's tile lists into a texture (`blend`), in the
dispatches of its plan (one unless the driver caps loops: `limits`)."""

from __future__ import annotations

from ...model.camera import Camera
from ..control import RenderControl
from ..types import Mode, RenderSettings
from . import interface as gi
from .gpu import Gpu

WORD, VEC4 = gi.WORD_BYTES, gi.VEC4_BYTES


def blend_defines(mode: Mode, supersample: int, precision: str = "exact") -> dict[str, int]:
    """The defines of blend.comp's variant for a frame (its header lists them); precision as RenderSettings'."""
    fast = {"GB_FAST": 1} if precision == "fast" and mode == Mode.GAUSSIAN_BLENDING else {}
    return {f"BLEND_MODE_{mode.name}": 1, "SUPERSAMPLED": int(supersample > 1), **fast}


def planes(gpu: Gpu, settings: RenderSettings, n: int | None = None):
    """stochastic_popfree's per-splat depth planes (popfree.h; preprocess.comp writes them, blend.comp reads them),
    sized for n splats (None: as preprocess sized them); a dummy in the other modes."""
    if settings.mode != Mode.STOCHASTIC_POPFREE:
        return gpu.ensure("dummy", VEC4)
    return gpu.buffers["planes"] if n is None else gpu.ensure("planes", n * VEC4, "depth planes")


def blend(
    gpu: Gpu,
    camera: Camera,
    settings: RenderSettings,
    want_window: bool,
    plan,
    longest: int,
    splats,
    tvals,
    ranges,
    rays,
    oit: tuple,
    control: RenderControl,
    target=None,
) -> None:
    """blend.comp into `target` or the output texture, in the dispatches of `plan` (one unless the driver caps
    loops); `rays`: the per-pixel sorted modes' ray data (else None)."""
    N = settings.supersample
    W, H = camera.width, camera.height
    RW, RH = W * N, H * N
    gx, gy = -(-RW // gi.TILE), -(-RH // gi.TILE)
    tex = gpu.ensure_texture(W, H) if target is None else target
    evals = gpu.ensure("evals", W * H * WORD, "evaluation counts")
    window = gpu.ensure("window", W * H * gi.WINDOW_WORDS * WORD if want_window else VEC4, "window sizes")
    bx, by = -(-W // gi.TILE), -(-H // gi.TILE)
    invocations = bx * by * gi.TILE * gi.TILE if len(plan) > 1 else 0  # state kept between dispatches
    state = gpu.ensure("blend_state", invocations * gi.BLEND_STATE_VEC4S * VEC4, "blend state")
    accum = gpu.ensure("blend_accum", invocations * gi.BLEND_ACCUM_VEC4S * VEC4, "blend sums")
    prog = gpu.program("blend.comp", **blend_defines(settings.mode, N, settings.precision))
    gpu.set(
        prog,
        out_size=(W, H),
        supersample=N,
        grid=(gx, gy),
        background=tuple(settings.background),
        want_window=int(want_window),
        oit=oit,
        stochastic=(settings.seed, settings.frame),
        queue=settings.queue,
    )
    cell_of = gpu.buffers["cell_of"] if settings.mode == Mode.DUPLEX else gpu.ensure("dummy", VEC4)
    depth_planes = planes(gpu, settings)
    for i, buf in enumerate(
        (splats, tvals, ranges, evals, window, state, accum, cell_of, depth_planes, rays or gpu.ensure("dummy", VEC4))
    ):
        buf.bind_to_storage_buffer(i)
    tex.bind_to_image(0, read=False, write=True)
    tiles = N * N
    for step, (sub0, sub1, c0, c1) in enumerate(plan):
        control.step(step, len(plan))
        gpu.set(
            prog,
            subtile_begin=sub0,
            subtile_end=sub1,
            chunk_begin=c0,
            chunk_end=c1,
            load_state=int(c0 > 0),
            store_state=int(c1 < longest),
            load_accum=int(sub0 > 0),
            store_accum=int(sub1 < tiles),
        )
        prog.run(bx, by, 1)
        gpu.ctx.memory_barrier()
    control.step(len(plan), len(plan))
