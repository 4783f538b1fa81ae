"""Drivers that cap the loop iterations of one shader invocation, and the split blend that works under the cap.

Mesa's llvmpipe ends every loop of an invocation once it has run 65535 iterations in total, silently, so a 100k-splat
tile list would be cut short. `loop_limit()` measures the cap once per context; when a frame's longest tile list does
not fit under it, blend.comp runs as several dispatches (`plan_blend`: groups of render tiles, windows of the lists)
that keep the per-pixel state in a buffer in between. Without a cap, the plan is one dispatch.
"""

from __future__ import annotations

import weakref

import numpy as np

from ...core.errors import RenderError
from . import interface as gi
from .context import shader_source
from .gpu import WG, Gpu

LOOP_PROBE = 1 << 20
FULL = 2**31 - 1  # a chunk end past any tile list

_loop_limits: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


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
    if limit is None:
        return [(0, tiles, 0, FULL)]
    budget = limit - 2 * tiles - 1024

    def cost(n: int) -> int:
        return n + 2 * -(-n // 256) + 4

    if cost(longest) <= budget:
        group = max(1, min(tiles, budget // cost(longest)))
        return [(t, min(t + group, tiles), 0, FULL) for t in range(0, tiles, group)]
    chunk = 256
    while cost(chunk + 256) <= budget:
        chunk += 256
    if cost(chunk) > budget:
        raise RenderError(f"glsl backend: the driver allows only {limit} loop iterations per invocation")
    return [(t, t + 1, c, c + chunk) for t in range(tiles) for c in range(0, longest, chunk)]


def plan_sorted(supersample: int, longest: int, limit: int | None, queue: int) -> list[tuple[int, int, int, int]]:
    """The one blend dispatch of a per-pixel sorted mode (its queue is not carried between dispatches), when its loops
    fit under `limit`: per render tile, stopthepop's hierarchy with a queue of K > 0 (resort.glsl: hier_walk) costs up
    to K + 80 iterations per splat (the 4x4 queue's insertion shifts and drops, the 2x2 merge, the pixel queue's
    shifts) and 2 K + 160 at the end, the exact order (K = 0) a pass over the list per blended splat."""
    tiles = supersample * supersample
    if limit is not None:
        per_tile = longest * (queue + 80) + 2 * queue + 160 if queue > 0 else (longest + 1) * (longest + 2) + 8
        if tiles * per_tile + 2 * tiles + 1024 > limit:
            raise RenderError(
                f"glsl backend: a per-pixel sorted frame with tile lists of {longest} splats needs up to "
                f"{tiles * per_tile} loop iterations per pixel, more than this driver allows ({limit}); "
                "use the cpu or cuda backend"
            )
    return [(0, tiles, 0, FULL)]


def blend_plan(
    gpu: Gpu, supersample: int, ranges, num_tiles: int, pairs: int, queue: int | None = None
) -> tuple[list, int]:
    """The blend dispatches for this frame and its longest tile list (0 when the context has no cap: not measured);
    `queue`: a per-pixel sorted mode's queue length (0: the exact order; None: not such a mode)."""
    limit = loop_limit(gpu.ctx)
    longest = 0
    if limit is not None and pairs > 0:
        gpu.run("list_max.comp", -(-num_tiles // WG), (ranges, gpu.buffers["totals"]), n=num_tiles)
        longest = int(np.frombuffer(gpu.buffers["totals"].read(size=gi.TOTALS_BYTES), np.uint32)[gi.TOTAL_MAX_LIST])
    if queue is not None:
        return plan_sorted(supersample, longest, limit, queue), longest
    return plan_blend(supersample, longest, limit), longest
