"""Sampling rates (pixels per unit of scene, relative to the pane): the x1/8 .. x8 steps, the slider, labels, the
render size of a pane, and the resolution drop and level-of-detail cut while the camera moves."""

from __future__ import annotations

import math

RATE_STEPS = (8.0, 4.0, 2.0, 1.0, 0.5, 0.25, 0.125)
RATE_MIN, RATE_MAX = 0.125, 8.0


def clamp_rate(rate: float) -> float:
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        return 1.0
    return float(min(RATE_MAX, max(RATE_MIN, rate)))


def step_rate(rate: float, direction: int) -> float:
    """The next step of RATE_STEPS above (direction > 0, more pixels) or below (direction < 0) `rate`.

    From a continuous value between two steps this goes to the neighbouring step in that direction.
    """
    rate = clamp_rate(rate)
    eps = 1e-9
    if direction > 0:
        above = [s for s in RATE_STEPS if s > rate * (1 + eps)]
        return min(above) if above else RATE_MAX
    below = [s for s in RATE_STEPS if s < rate * (1 - eps)]
    return max(below) if below else RATE_MIN


def rate_to_slider(rate: float) -> float:
    """log2 of the rate: the slider runs linearly from -3 (x1/8) to 3 (x8)."""
    return math.log2(clamp_rate(rate))


def slider_to_rate(value: float, snap: float = 0.04) -> float:
    """Inverse of rate_to_slider; values within `snap` (log2 units) of a step snap onto it."""
    value = min(3.0, max(-3.0, float(value)))
    nearest = round(value)
    if abs(value - nearest) <= snap:
        value = nearest
    return clamp_rate(2.0**value)


def render_size(width: int, height: int, rate: float) -> tuple[int, int]:
    """The render resolution of a pane of width x height display pixels at `rate` (as Camera.at_sampling_rate)."""
    return max(1, round(width * rate)), max(1, round(height * rate))


# ---- resolution drop while the camera moves ------------------------------------------------------------------------

PREVIEW_FACTORS = (1.0, 0.5, 0.25, 0.125)


def preview_factor(pixels: int, ms_per_pixel: float | None, budget_ms: float, moving: bool) -> float:
    """Fraction of the render resolution (per axis) to use while the camera moves, so that one render takes about
    `budget_ms`; 1 when still, when nothing was measured yet, or when the full render fits the budget."""
    if not moving or not ms_per_pixel or ms_per_pixel <= 0 or pixels <= 0:
        return 1.0
    for f in PREVIEW_FACTORS:
        if pixels * f * f * ms_per_pixel <= budget_ms or f == PREVIEW_FACTORS[-1]:
            return f
    return PREVIEW_FACTORS[-1]


# ---- level-of-detail cut of the previews ----------------------------------------------------------------------------

PREVIEW_LOD_PX = 1.0  # the finest cut a preview draws (pixels of the preview's resolution)
MAX_PREVIEW_LOD = 32.0
PREVIEW_MS = 60.0  # a preview render's budget (the panes' previews of one camera render together): >= 10 a second


def first_preview_lod(num_splats: int) -> float:
    """A scene's first preview cut, before any preview of it has been timed: 8 px from 4 M splats, 4 from 2 M, 2 from
    1 M, else PREVIEW_LOD_PX. preview_lod then adapts it; starting from 1 px, a large scene's first orbit would work
    its way up through previews of seconds (at x1 a 1 px cut of a capture keeps nearly all its splats)."""
    return float(min(8.0, max(PREVIEW_LOD_PX, 2.0 ** math.floor(math.log2(max(num_splats, 1) / 500_000)))))


FIRST_PREVIEW_SPLATS = 2_000_000  # from this many splats a pane's first picture of a scene is a preview (at 1 M the
# full frame's first tiles came about as soon as a preview, whose render then delayed the final frame)
FIRST_PREVIEW = 0.25  # its fraction of the render resolution (per axis)


def first_preview(num_splats: int) -> float:
    """The resolution factor of a pane's first picture of a scene: FIRST_PREVIEW from FIRST_PREVIEW_SPLATS splats
    (it shows within a second while the full frame takes seconds; then the full frame refines over it), else 1 (the
    full frame at once)."""
    return FIRST_PREVIEW if num_splats >= FIRST_PREVIEW_SPLATS else 1.0


def preview_lod(tau: float, preview_ms: float) -> float:
    """The next preview's cut after one that took `preview_ms` at `tau` pixels: twice as coarse over the
    budget PREVIEW_MS, twice as fine under 40 % of it, between PREVIEW_LOD_PX and MAX_PREVIEW_LOD."""
    if preview_ms > PREVIEW_MS:
        return min(MAX_PREVIEW_LOD, tau * 2.0)
    if preview_ms < 0.4 * PREVIEW_MS:
        return max(PREVIEW_LOD_PX, tau / 2.0)
    return tau
