"""The memory one evaluated view needs, estimated from its photo's size before any decoding or rendering and
refused in one line beyond the memory budget (`render.budget.memory_budget`, GBVIEWER_MEMORY_BUDGET)."""

from __future__ import annotations

from typing import Sequence

from ..core.errors import GBViewerError
from ..io.datasets import View
from ..render import RenderSettings
from ..render.budget import BUDGET_ENV, frame_bytes, gib, memory_budget
from .multiscale import camera_for_rate, rate_factor

DECODE_BYTES = 40  # per photo pixel: the decoded RGBA bytes (PIL and numpy) and its float32 copy and quotient
LEVEL_BYTES = 28  # per ground-truth pixel at each rate: the float32 RGBA level and its composited RGB
SSIM_BYTES = 200  # per compared pixel: both images clipped and in float64, skimage's filtered moments per channel
FRAME_RGB_BYTES = 12  # per rendered pixel: the frame's float32 RGB held while it is measured


def view_bytes(view: View, settings: Sequence[RenderSettings], rates: Sequence[float]) -> int:
    """Bytes evaluating `view` needs at once: the photo decoded, its ground truths at every rate, SSIM's working
    memory at the largest rate and the largest render (every mode and supersampling at every rate)."""
    w, h = view.camera.width, view.camera.height
    cams = [camera_for_rate(view.camera, r) for r in rates]
    levels = sum(w // rate_factor(r) * (h // rate_factor(r)) for r in rates) * LEVEL_BYTES
    largest = max(c.width * c.height for c in cams)
    render = max(frame_bytes(c, s, 0) + c.width * c.height * FRAME_RGB_BYTES for c in cams for s in settings)
    return w * h * DECODE_BYTES + levels + largest * SSIM_BYTES + render


def check_view_memory(
    view: View, settings: Sequence[RenderSettings], rates: Sequence[float], fmt: str, processes: int = 1
) -> None:
    """A one-line `GBViewerError` when `processes` views at once (`view_bytes` each) exceed the memory budget."""
    need = view_bytes(view, settings, rates) * processes
    budget, source = memory_budget()
    if need > budget:
        smaller = "" if fmt == "blender" else " or evaluate downsampled photos (e.g. --images images_4)"
        each = f" ({processes} workers at once)" if processes > 1 else ""
        raise GBViewerError(
            f"{view.image}: the {view.camera.width}x{view.camera.height} photo needs about "
            f"{gib(need)}{each} to evaluate (decode, ground truths, SSIM, renders), more than the "
            f"{gib(budget)} budget ({source}); set {BUDGET_ENV} (e.g. {BUDGET_ENV}=64G) to raise it"
            f"{smaller}"
        )
