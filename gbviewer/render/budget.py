"""The memory budget of one frame: its buffers estimated from the camera, the supersampling and the splat count, and
refused in one line before any of them is allocated when they exceed what the machine has (or GBVIEWER_MEMORY_BUDGET
allows)."""

from __future__ import annotations

import os
import re
import resource

from ..core.errors import RenderError
from ..model.camera import Camera
from .types import Mode, RenderSettings

BUDGET_ENV = "GBVIEWER_MEMORY_BUDGET"  # bytes, or with a K, M, G or T suffix (powers of 1024)
SAMPLE_BYTES = 20  # per rendered sample: RGB and alpha (float32), evaluations (int32)
WINDOW_BYTES = 8  # per sample of a Gaussian blending frame: its transmittance window (2 x float32)
PIXEL_BYTES = 48  # per output pixel: the downsampled frame and its copies into numpy arrays
SPLAT_BYTES = 160  # per splat: its projected footprint, tile rectangle and at least one tile-list entry
TILE = 16  # pixels per tile side (gbv::TILE)
TILE_BYTES = 8 * 65  # per tile: its list start and the binning counters of up to 64 ranges
SUFFIXES = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
BUDGET_RE = re.compile(r"(\d{1,20}(?:\.\d{1,20})?|\.\d{1,20})\s*([KMGT]?)", re.IGNORECASE)


def frame_bytes(camera: Camera, settings: RenderSettings, splats: int, size: tuple[int, int] | None = None) -> int:
    """A lower bound of the bytes one frame allocates: its sample buffers at the supersampled size, the output
    pixels, the per-tile and per-splat buffers (the tile lists grow beyond one entry per splat with the
    footprints, known only after projecting). `size`: the (width, height) of the part of the image rendered (a
    region of the CPU renderer), by default all of it."""
    n = settings.supersample
    w, h = size or (camera.width, camera.height)
    samples = w * h * n * n
    tiles = -(-w * n // TILE) * -(-h * n // TILE)
    window = WINDOW_BYTES if settings.mode == Mode.GAUSSIAN_BLENDING else 0
    return samples * (SAMPLE_BYTES + window) + w * h * PIXEL_BYTES + tiles * TILE_BYTES + splats * SPLAT_BYTES


def _available() -> tuple[int, str]:
    """Bytes this process may still allocate, and where the figure comes from: MemAvailable of /proc/meminfo (or
    the physical memory), lowered to the room left under an address-space limit (ulimit -v)."""
    try:
        with open("/proc/meminfo") as fh:
            info = dict(line.split(":", 1) for line in fh)
        avail, source = int(info["MemAvailable"].split()[0]) * 1024, "available memory"
    except (OSError, KeyError, ValueError):
        avail, source = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"), "physical memory"
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit != resource.RLIM_INFINITY:
        try:
            with open("/proc/self/statm") as fh:
                used = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            used = 0
        if limit - used < avail:
            avail, source = max(limit - used, 0), "room under the address-space limit (ulimit -v)"
    return avail, source


def memory_budget() -> tuple[int, str]:
    """(bytes, what they are): GBVIEWER_MEMORY_BUDGET when set (and not empty), else what the machine has
    available now."""
    text = os.environ.get(BUDGET_ENV, "")
    if not text:
        return _available()
    match = BUDGET_RE.fullmatch(text.strip())
    value = float(match[1]) * SUFFIXES.get(match[2].upper(), 1) if match else 0.0
    if value < 1:
        raise RenderError(
            f"{BUDGET_ENV}: expected bytes >= 1, as a decimal number with an optional K, M, G or T "
            f"suffix (powers of 1024; 1.5G), got {text!r:.40}"
        )
    return int(value), BUDGET_ENV


def gib(n: int) -> str:
    """n bytes in GiB, three significant digits."""
    return f"{n / (1 << 30):.3g} GiB"


def check_frame_memory(
    camera: Camera, settings: RenderSettings, splats: int, size: tuple[int, int] | None = None
) -> None:
    """Raise a one-line `RenderError` when the frame's buffers (`frame_bytes`, of the part `size`) exceed the
    memory budget."""
    need = frame_bytes(camera, settings, splats, size)
    budget, source = memory_budget()
    if need > budget:
        w, h = size or (camera.width, camera.height)
        raise RenderError(
            f"{w}x{h} at supersample {settings.supersample} needs at least "
            f"{gib(need)} for its buffers, more than the {gib(budget)} budget ({source}); render "
            f"smaller or set {BUDGET_ENV} (e.g. {BUDGET_ENV}=64G) to raise it"
        )
