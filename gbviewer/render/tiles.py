"""Stills and video frames of any size: a frame whose buffers exceed the memory budget (`budget.frame_bytes`) is
rendered in parts (`CpuRenderer.render_region`) and stitched, instead of being refused.

What is exact: every part is rendered with the whole image's camera, so its culling, frustum limits (the EWA
Jacobian's clamp depends on the image size and principal point), level-of-detail cut and tile grid are the whole
image's, and its pixel and sample positions are the whole image's coordinates; a part starts on a whole native tile
of the supersampled grid and on a whole output pixel. Each tile's list is therefore the whole frame's list of that
tile, in the same depth order, and the stitched image (rgb, alpha, evaluations, Gaussian Blending's window) equals
the whole render bit for bit in every mode the parts support: all but duplex (its cells are culled by the whole
image's tiles; it is rendered whole, or refused by the budget as before). The stochastic modes hash whole-image
pixel coordinates, so their noise is the whole frame's too. Only the CPU backend renders parts; the other backends
render whole frames.
"""

from __future__ import annotations

from dataclasses import replace
from math import gcd
from typing import Callable

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import RenderCancelled, RenderError
from ..model.camera import Camera
from .budget import BUDGET_ENV, frame_bytes, gib, memory_budget
from .contract import Renderer
from .cpu import REGION_ALIGN, Region
from .types import Frame, FrameStats, Mode, RenderSettings

STITCH_BYTES = 20  # per output pixel held while the parts render: rgb and alpha (float32), evaluations (int32)
WINDOW_STITCH_BYTES = 8  # and Gaussian Blending's window plane (2 x float32) when asked for
SUMMED = ("preprocess_ms", "sort_ms", "blend_ms", "total_ms", "sort_length", "sort_bytes", "pairs", "evaluations")


def region_step(settings: RenderSettings) -> int:
    """The output pixels a part's origin steps by: the least x with x * supersample a multiple of the native tile."""
    return REGION_ALIGN // gcd(REGION_ALIGN, settings.supersample)


def plan_parts(
    camera: Camera, settings: RenderSettings, splats: int, budget: int, source: str = "given"
) -> list[Region] | None:
    """The parts (x, y, w, h) a frame renders in under `budget` bytes (None: whole, it fits), the stitched image
    counted; halves the longer side of the part (on `region_step`) until it fits. A one-line `RenderError` when
    not even the smallest part does (`source`: where the budget comes from, as `memory_budget` says)."""
    if frame_bytes(camera, settings, splats) <= budget:
        return None
    W, H = camera.width, camera.height
    held = W * H * (STITCH_BYTES + (WINDOW_STITCH_BYTES if settings.debug == "window" else 0))
    step = region_step(settings)
    w, h = W, H
    while frame_bytes(camera, settings, splats, (w, h)) > budget - held:
        if w <= step and h <= step:
            raise RenderError(
                f"{W}x{H} at supersample {settings.supersample}: even {w}x{h} parts need "
                f"{gib(frame_bytes(camera, settings, splats, (w, h)) + held)} with the stitched image, "
                f"more than the {gib(budget)} budget ({source}); set {BUDGET_ENV} to raise it"
            )
        if w >= h:
            w = max(step, -(-w // 2 // step) * step)
        else:
            h = max(step, -(-h // 2 // step) * step)
    return [(x, y, min(w, W - x), min(h, H - y)) for y in range(0, H, h) for x in range(0, W, w)]


def render_tiled(
    renderer: Renderer,
    camera: Camera,
    settings: RenderSettings,
    splats: int,
    *,
    cancel: Cancellable | None = None,
    progress: Callable[[int, int], None] | None = None,
    budget: int | None = None,
) -> Frame:
    """`renderer.render(camera, settings)` of a scene of `splats` splats, in parts when its buffers exceed the
    memory budget (`memory_budget`, or `budget` bytes) and the renderer renders parts (`render_region`; not
    duplex). progress(done, total) after each part; a cancel set between or during parts raises RenderCancelled.
    A stitched frame's stats add up the parts' times and counts; its visible is the most splats one part drew."""
    parts = None
    if hasattr(renderer, "render_region") and settings.mode != Mode.DUPLEX:
        parts = plan_parts(camera, settings, splats, *(memory_budget() if budget is None else (budget,)))
    if parts is None:
        return renderer.render(camera, settings, cancel=cancel)
    W, H = camera.width, camera.height
    rgb = np.empty((H, W, 3), np.float32)
    alpha = np.empty((H, W), np.float32)
    debug: dict[str, np.ndarray] = {}
    stats: FrameStats | None = None
    for i, (x, y, w, h) in enumerate(parts):
        if cancel is not None and cancel.is_set():
            raise RenderCancelled("render cancelled")
        f = renderer.render_region(camera, settings, (x, y, w, h), cancel=cancel)
        rgb[y : y + h, x : x + w], alpha[y : y + h, x : x + w] = f.rgb, f.alpha
        for name, plane in f.debug.items():
            debug.setdefault(name, np.empty((H, W, *plane.shape[2:]), plane.dtype))[y : y + h, x : x + w] = plane
        stats = (
            f.stats
            if stats is None
            else replace(
                stats,
                visible=max(stats.visible, f.stats.visible),
                **{k: getattr(stats, k) + getattr(f.stats, k) for k in SUMMED},
            )
        )
        if progress is not None:
            progress(i + 1, len(parts))
    assert stats is not None  # at least one part
    return Frame(rgb, alpha, replace(stats, evals_per_pixel=stats.evaluations / (W * H)), debug)
