"""Pixel traces: what the native CPU blend did at one output pixel, list entry by list entry (`trace_pixel`).

The trace is produced by the kernel itself: the CPU module blends the pixel's sub-samples through the scalar path's
tile code (the per-lane steps every backend shares, which the vector paths are tested equal to) with a recording
tracer (native/cpu/trace.cpp). Nothing here recomputes the blend.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.errors import InvalidValue, RenderError
from ..core.validate import dumps_json, integer
from ..model.camera import Camera
from ..model.scene import Scene
from .registry import capable, get_renderer
from .types import Mode, RenderSettings, settings_from

# Why a list entry added nothing (gbv::Skip in native/include/gbv/trace.h, by value); "" when it added.
SKIP_REASONS = (
    "",
    "outside_box",  # the pixel centre (gaussian_blending: window) is outside the splat's box: not evaluated
    "outside_radius",  # duplex: pixel outside the splat's radius; gaussian_blending: window beyond radius + reach
    "invalid_exponent",  # Gaussian exponent > 0 or NaN
    "below_cutoff",  # exponent below ln(min_alpha / opacity) (gaussian_blending: largest value on the window)
    "alpha_below_min",  # alpha below 1/255 (gaussian_blending: 1/256)
    "early_stop",  # T (1 - alpha) < 1e-4: the pixel stops without this splat
    "cell_stop",  # duplex: a new cell entered with T < 0.01: the pixel stops
    "terminated",  # after the pixel stopped: not evaluated
    "discarded",  # stochastic: the fragment's uniform is not below its alpha
    "depth_test",  # stochastic_popfree: kept, but behind the nearest fragment kept so far
)
_FALLBACK, _STOPPED = 1, 2  # native flags


class TraceStep(NamedTuple):
    """One entry of the pixel's tile list at one sub-sample, in blend order.

    Positions and sizes are in output pixels (sub-sample coordinates divided by the supersampling factor):
    `mean` the splat's centre, `conic` its inverse 2D covariance (a, b, c) and `covariance` (xx, xy, yy), `radius` its
    bounding radius, `cutoff` the Mahalanobis radius where its value falls to the mode's threshold (1/255, 1/256).

    `alpha`: scalar, mip, wsr, duplex: at the sample centre (duplex: before dividing by E); analytic: integrated over
    the pixel; gaussian_blending: averaged over the window (`fallback`: at the window centre). `raw_weight`: what the
    kernel added to its sums (alpha T; wsr: alpha; duplex: alpha / E T_cell); `weight`: the share of the sample's
    colour, raw_weight / the sample's total (wsr, duplex; the same number elsewhere), so a sample's colour is
    sum(weight * color) + transmittance * background. 0 where the kernel computed or added nothing. `T_before`,
    `T_after`: the sample's transmittance (duplex: the product of (1 - alpha/E); wsr: 1). gaussian_blending:
    `window_center`, `window_size` after the entry; duplex: `cell` and `T_cell` after it.

    `index`: the scene's splat, or with level of detail (`node`) where the cut drew an interior node of the scene's
    hierarchy in place of its splats, that node's flat id (gbviewer.lod.Hierarchy: num_splats + its interior
    index); `source` says which.
    """

    sample: int
    index: int  # the scene's splat, or (node) the hierarchy's interior node drawn in place of its splats
    depth: float
    rejected: str  # a SKIP_REASONS entry; "" when the splat added to the pixel
    alpha: float
    weight: float
    raw_weight: float
    T_before: float
    T_after: float
    color: tuple[float, float, float]
    opacity: float
    mean: tuple[float, float]
    conic: tuple[float, float, float]
    covariance: tuple[float, float, float]
    radius: float
    cutoff: float
    fallback: bool
    stopped: bool  # the sample stopped at this entry
    window_center: tuple[float, float] | None = None
    window_size: tuple[float, float] | None = None
    cell: int | None = None
    T_cell: float | None = None
    node: bool = False

    @property
    def source(self) -> str:
        """What the entry drew: "splat 12", or "node 1234" (level of detail: an interior node of the hierarchy)."""
        return f"{'node' if self.node else 'splat'} {self.index}"

    @property
    def short(self) -> str:
        """`source` in a column headed "splat": "12", or "node 1234"."""
        return f"node {self.index}" if self.node else str(self.index)


@dataclass(frozen=True)
class SampleTrace:
    """One sub-sample of the pixel: its centre (output pixels), colour and transmittance as rendered, the sum its
    weights were divided by (wsr, duplex; 1 otherwise) and its list entries."""

    position: tuple[float, float]
    color: tuple[float, float, float]
    transmittance: float
    total: float
    steps: tuple[TraceStep, ...]


@dataclass(frozen=True)
class PixelTrace:
    """The trace of output pixel (x, y) in `mode` (a RenderSettings label) with `supersample`^2 samples: `color` the
    pixel as rendered (background included, the samples' average), `transmittance` = 1 - Frame.alpha there."""

    mode: str
    x: int
    y: int
    supersample: int
    width: int
    height: int
    background: tuple[float, float, float]
    color: tuple[float, float, float]
    transmittance: float
    samples: tuple[SampleTrace, ...]

    @property
    def steps(self) -> tuple[TraceStep, ...]:
        """Every sample's entries, sample by sample (each step names its sample)."""
        return tuple(s for sample in self.samples for s in sample.steps)

    def contributions(self) -> list[tuple[int, float]]:
        """(index, share of the pixel colour) of the splats (level of detail: or hierarchy nodes, TraceStep.node)
        that added, largest share first: the pixel is sum(share * colour) + transmittance * background."""
        share: Counter[int] = Counter()
        n = len(self.samples)
        for s in self.steps:
            if not s.rejected:
                share[s.index] += s.weight / n
        return share.most_common()

    def rejected_counts(self) -> dict[str, int]:
        """How many entries each reason rejected, over every sample."""
        return dict(Counter(s.rejected for s in self.steps if s.rejected))

    def to_dict(self) -> dict:
        """Plain data: the fields, each sample's fields with its steps as dicts."""
        samples = [
            {
                "position": s.position,
                "color": s.color,
                "transmittance": s.transmittance,
                "total": s.total,
                "steps": [step._asdict() for step in s.steps],
            }
            for s in self.samples
        ]
        fields = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "samples"}
        return {**fields, "samples": samples}

    def to_json(self, indent: int | None = None) -> str:
        """The trace as strict JSON (what `gbviewer trace --json` writes, one per mode): a number that is not
        finite (a footprint or weight that over- or underflowed for a far or tiny-focal camera) is null."""
        return dumps_json(self.to_dict(), indent=indent)


def _rows(a: np.ndarray) -> list[tuple]:
    return list(map(tuple, a.tolist()))


def from_native(out: dict, settings: RenderSettings, camera: Camera, x: int, y: int, num_splats: int) -> PixelTrace:
    """A PixelTrace from the CPU module's Renderer.trace(..., x=x, y=y) result (native/cpu/trace.cpp's columns) of a
    scene of `num_splats` splats (an index past them: a level-of-detail cut's interior node, drawn in place)."""
    n = settings.supersample
    mode = settings.mode
    xy, conic = out["xy"] / n, out["conic"].astype(np.float64) * n * n
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # non-finite entries: null in JSON
        det = conic[:, 0] * conic[:, 2] - conic[:, 1] ** 2
        cov = np.stack([conic[:, 2], -conic[:, 1], conic[:, 0]], 1) / det[:, None]
    cutoff = np.sqrt(np.maximum(-2.0 * out["log_min_alpha"].astype(np.float64), 0.0))
    totals = out["sample_total"].astype(np.float64)
    weight = out["weight"] / totals[out["sample"]]
    window = out["window"] / n
    cols = dict(
        sample=out["sample"].tolist(),
        index=out["index"].tolist(),
        depth=out["depth"].tolist(),
        rejected=[SKIP_REASONS[k] for k in out["skip"]],
        alpha=out["alpha"].tolist(),
        weight=weight.tolist(),
        raw_weight=out["weight"].tolist(),
        T_before=out["T_before"].tolist(),
        T_after=out["T_after"].tolist(),
        color=_rows(out["color"]),
        opacity=out["opacity"].tolist(),
        mean=_rows(xy),
        conic=_rows(conic),
        covariance=_rows(cov),
        radius=(out["radius"] / n).tolist(),
        cutoff=cutoff.tolist(),
        fallback=((out["flags"] & _FALLBACK) != 0).tolist(),
        stopped=((out["flags"] & _STOPPED) != 0).tolist(),
        node=(out["index"] >= num_splats).tolist(),
    )
    if mode == Mode.GAUSSIAN_BLENDING:
        cols.update(window_center=_rows(window[:, :2]), window_size=_rows(window[:, 2:]))
    if mode == Mode.DUPLEX:
        cols.update(cell=out["cell"].tolist(), T_cell=out["T_cell"].tolist())
    absent = [None] * len(cols["index"])
    steps = list(map(TraceStep._make, zip(*(cols.get(f, absent) for f in TraceStep._fields))))
    rgb, alpha = out["sample_rgb"], out["sample_alpha"]
    samples, start = [], 0
    for k in range(n * n):
        end = start
        while end < len(steps) and steps[end].sample == k:
            end += 1
        pos = ((x * n + k % n + 0.5) / n, (y * n + k // n + 0.5) / n)
        samples.append(
            SampleTrace(
                pos, tuple(float(v) for v in rgb[k]), float(1.0 - alpha[k]), float(totals[k]), tuple(steps[start:end])
            )
        )
        start = end
    return PixelTrace(
        settings.label,
        x,
        y,
        n,
        camera.width,
        camera.height,
        tuple(settings.background),
        tuple(float(v) for v in out["pixel_rgb"]),
        float(1.0 - out["pixel_alpha"]),
        tuple(samples),
    )


def check_pixel(camera: Camera, x: object, y: object) -> tuple[int, int]:
    """(x, y) as ints inside the camera's image; a one-line RenderError otherwise."""
    try:
        xi, yi = integer(x, "pixel x"), integer(y, "pixel y")
    except InvalidValue as exc:
        raise RenderError(str(exc)) from None
    if not (0 <= xi < camera.width and 0 <= yi < camera.height):
        raise RenderError(
            f"pixel ({xi}, {yi}) is outside the {camera.width}x{camera.height} image "
            f"(x in 0..{camera.width - 1}, y in 0..{camera.height - 1})"
        )
    return xi, yi


def trace_pixel(
    scene: Scene,
    camera: Camera,
    x: int,
    y: int,
    mode: str | Mode | RenderSettings = "scalar",
    supersample: int | None = None,
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    sh_degree: int | None = None,
    **options,
) -> PixelTrace:
    """The trace of pixel (x, y) of `camera`'s image rendered in `mode` (a RenderSettings, or a spec parsed as
    `gbviewer.render` parses it, with N x N `supersample`, `sh_degree` and `options`: depth_correct, et_grade,
    cell_size, lod, seed and frame (stochastic)), by the kernel of the first backend that traces pixels
    (`Capabilities.trace`: the CPU backend; the others are held to it by their tests)."""
    settings = settings_from(mode, "trace_pixel", background, supersample=supersample, sh_degree=sh_degree, **options)
    xi, yi = check_pixel(camera, x, y)
    return get_renderer(scene, capable("trace")[0]).trace(camera, settings, xi, yi)


__all__ = ["SKIP_REASONS", "PixelTrace", "SampleTrace", "TraceStep", "check_pixel", "from_native", "trace_pixel"]
