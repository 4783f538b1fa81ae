"""The render layer's types: RenderSettings, Frame and its FrameStats, constants; Mode and its groups re-exported
from gbviewer.render.modes. The Renderer contract and its Capabilities are in gbviewer.render.contract.

Imports no backend."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.errors import InvalidValue, RenderError
from ..core.validate import array, distinct_items, integer, real
from ..model.scene import Scene
from .modes import MAX_QUEUE, MAX_SEED, STOCHASTIC_MODES, STOPTHEPOP_QUEUE, Mode
from .presets import FILTERED_MODES, PRESETS
from .spec import PRECISIONS, shortest, shown, spec_parts
from .view_filter import ViewFilter

DEBUG_OUTPUTS = ("none", "window")
DEFAULT_ET_GRADE = 4.0  # Duplex-GS ET_grade_final, the value training ends with (docs/modes.md#duplex)
DEFAULT_SIGMA = 10.0  # sort-free GS's initial sigma, for depth correction on scenes without a trained one
MAX_SUPERSAMPLE = 8
MAX_THREADS = 1024
MAX_CELL_SIZE = 1 << 20
MAX_LOD = 1e6  # pixels: a cut of the root alone long before
SORT_ENTRY_BYTES = 24  # per sorted key: 8-byte key + 4-byte value, input and output buffers (CUB SortPairs)


@dataclass(frozen=True)
class RenderSettings:
    """How to render, field by field (every number checked in __post_init__; docs/modes.md has each mode's rule).

    mode: the blending mode (`Mode`, or its name).
    supersample: N x N samples per pixel (1..8), box-averaged.
    background: RGB the final transmittance shows (float32).
    sh_degree: cap on the SH degree evaluated (0..3).
    debug: "none", or "window" to add the final Gaussian Blending window size per pixel (H, W, 2) to `Frame.debug`.
    threads: CPU threads (0: all).
    depth_correct (wsr, duplex): multiply each splat's weight by LC-WSR's max(0, 1 - z/sigma) (sigma: the scene's
        trained value, else 10).
    et_grade (duplex): Duplex-GS's E (None: the scene's trained value, else 4.0, the published final value).
    cell_size (duplex): splats per cell built for scenes without cells.
    lod: render the cut of the scene's splat hierarchy at this projected size in pixels (>= 0; gbviewer.lod,
        docs/lod.md) in any mode; None renders every splat.
    view_filter (scalar, stochastic, stochastic_popfree): the 2D filter and the presets' rules (default 3DGS's
        +0.3 px^2).
    preset: the viewer preset the settings came from ('preset:NAME', gbviewer.render.presets), or "".
    seed, frame (stochastic modes; other modes refuse anything but 0): the keep decisions' hash seed and frame index
        (uint32; same seed and frame, same bits; another frame, another sample).
    queue (stopthepop): the per-pixel queue length K after StopThePop's tile, 4x4 and 2x2 stages (0..64; 0:
        unbounded, the exact per-pixel sort without the hierarchy; default 4, as published), spelled 'stopthepop:K'
        (and 'stopthepop:K:N' with N x N supersampling).
    precision (gaussian_blending): "exact", or "fast" (spec suffix '+fast'): the fast kernel stays within 1/1024 of
        the exact one per channel and in alpha (tests/render/test_gb_fast.py). The library, `eval`, `flicker`,
        `bench` and `trace` render exact unless asked; the viewer's panes and the pictures of `render`, `compare`,
        `video` and `demo` fast (`parse`'s default_precision). Other modes have one kernel: always "exact".
    """

    mode: Mode = Mode.SCALAR
    supersample: int = 1
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int = 3
    debug: str = "none"
    threads: int = 0  # CPU threads, 0 = all
    depth_correct: bool = False
    et_grade: float | None = None
    cell_size: int = 5
    lod: float | None = None  # level of detail: draw the hierarchy's cut at this many pixels (None: every splat)
    view_filter: ViewFilter = ViewFilter()
    preset: str = ""
    seed: int = 0  # stochastic modes: the keep decisions' hash seed (gbv/stochastic.h); same seed and frame, same bits
    frame: int = 0  # stochastic modes: the frame index (another index, another sample)
    queue: int = STOPTHEPOP_QUEUE
    precision: str = "exact"  # gaussian_blending: "fast" within the stated bound of "exact"

    def __post_init__(self) -> None:
        """Every number checked through gbviewer.core.validate (the native renderers take them as int32 and float32);
        a bad one is a one-line RenderError naming the field."""
        object.__setattr__(self, "mode", Mode.parse(self.mode))
        if self.precision not in PRECISIONS:
            raise RenderError(f"precision {self.precision!r}; expected one of {', '.join(PRECISIONS)}")
        if self.mode != Mode.GAUSSIAN_BLENDING:
            object.__setattr__(self, "precision", "exact")
        if self.debug not in DEBUG_OUTPUTS:
            raise RenderError(f"debug output {self.debug!r}; expected one of {DEBUG_OUTPUTS}")
        try:
            checked = {
                "supersample": integer(self.supersample, "supersample", lo=1, hi=MAX_SUPERSAMPLE),
                "background": tuple(array(self.background, "background", (3,), f32=True).tolist()),
                "sh_degree": integer(self.sh_degree, "sh_degree", lo=0, hi=3),
                "threads": integer(self.threads, "threads", lo=0, hi=MAX_THREADS),
                "et_grade": None
                if self.et_grade is None
                else real(self.et_grade, "et_grade", lo=0, lo_open=True, f32=True),
                "cell_size": integer(self.cell_size, "cell_size", lo=1, hi=MAX_CELL_SIZE),
                "lod": None if self.lod is None else real(self.lod, "lod", lo=0, hi=MAX_LOD, f32=True),
                **{k: integer(getattr(self, k), k, lo=0, hi=MAX_SEED) for k in ("seed", "frame")},
                "queue": integer(self.queue, "queue", lo=0, hi=MAX_QUEUE),
            }
        except InvalidValue as exc:
            raise RenderError(str(exc)) from None
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        object.__setattr__(self, "depth_correct", bool(self.depth_correct))
        if not isinstance(self.view_filter, ViewFilter):
            raise RenderError(f"view_filter {self.view_filter!r}; expected a gbviewer.render.ViewFilter")
        if self.mode != Mode.STOPTHEPOP and self.queue != STOPTHEPOP_QUEUE:
            raise RenderError(f"queue {self.queue} applies to the stopthepop mode, not {self.mode.label}")
        for key in ("seed", "frame"):
            if self.mode not in STOCHASTIC_MODES and getattr(self, key):
                raise RenderError(
                    f"{key} {getattr(self, key)} applies to the stochastic modes "
                    f"({', '.join(m.label for m in STOCHASTIC_MODES)}), not {self.mode.label}"
                )
        if self.mode.label not in FILTERED_MODES and not self.view_filter.is_default:
            raise RenderError(f"view_filter {self.view_filter.describe()} is not for {self.mode.label}")
        if self.preset:  # a name only: the settings must be the preset's, else they are labelled what they are not
            p = PRESETS.get(self.preset)
            if p is None or (Mode.parse(p.mode), p.view_filter, p.sh_degree) != (
                self.mode,
                self.view_filter,
                self.sh_degree,
            ):
                raise RenderError(
                    f"preset {self.preset!r}: "
                    + (
                        f"unknown; expected one of {', '.join(PRESETS)}"
                        if p is None
                        else f"is {p.describe()}; these settings are not (make them with RenderSettings.parse"
                        f"('preset:{p.name}'))"
                    )
                )

    def label_for(self, scene: Scene, lod_counts: tuple[int, int] | None = None) -> str:
        """The label with what the scene makes of the mode: wsr on a scene without trained view weights is an
        approximation (v = 1); duplex names where its cells come from; a level-of-detail frame the splats of its cut
        (`lod_counts`: drawn, of; else what a cut's Scene says)."""
        label = self.base_label
        oit = scene.oit
        neural = oit is not None and oit.neural is not None
        trained = neural or scene.meta.get("view_weights_in_opacity")
        if self.mode == Mode.WSR and (oit is None or oit.view_weight_sh is None) and not trained:
            label += " (approx.: v=1)"
        elif self.mode == Mode.DUPLEX and (oit is None or oit.cells is None) and not neural:
            label += f" (built cells, K={self.cell_size})"
        if self.lod is not None:  # the counts of the frame's cut (none without a frame: cuts vary by camera)
            label += f" LOD \u03c4={self.lod:g} px"
            counts = scene.meta.get("lod") if lod_counts is None else lod_counts
            if counts is not None:
                label += f", {counts[0]:,} of {counts[1]:,} splats"
        return label

    @property
    def name(self) -> str:
        """'scalar', 'preset:supersplat', 'stopthepop:8' (a queue other than the published 4), ..."""
        if self.preset:
            return f"preset:{self.preset}"
        return self.mode.label + (f":{self.queue}" if self.queue != STOPTHEPOP_QUEUE else "")

    @property
    def native_mode(self) -> int:
        """The mode word the native renderers take: the Mode, stopthepop's queue length in the bits above 8."""
        return int(self.mode) | (self.queue << 8 if self.mode == Mode.STOPTHEPOP else 0)

    @property
    def base_label(self) -> str:
        """The label without the level of detail: 'scalar 3x3', 'gaussian_blending fast', ..."""
        return (
            self.name
            + (f" {self.supersample}x{self.supersample}" if self.supersample > 1 else "")
            + (" fast" if self.precision == "fast" else "")
        )

    @property
    def label(self) -> str:
        return self.base_label + (f" LOD \u03c4={self.lod:g} px" if self.lod is not None else "")

    @property
    def spec(self) -> str:
        """The inverse of `parse` at its default precision (exact: a fast gaussian_blending says '+fast'):
        'gaussian_blending', 'scalar:3', 'preset:spark', 'scalar+lod:1', 'gaussian_blending:2+fast', ..."""
        lod = f"+lod:{shortest(self.lod)}" if self.lod is not None else ""
        name = f"stopthepop:{self.queue}" if self.mode == Mode.STOPTHEPOP and self.supersample > 1 else self.name
        fast = "+fast" if self.precision == "fast" else ""
        return name + (f":{self.supersample}" if self.supersample > 1 else "") + fast + lod

    @classmethod
    def parse(cls, spec: "str | Mode", *, default_precision: str = "exact", **options) -> "RenderSettings":
        """'MODE' or 'MODE:N' (N x N supersampling); 'stopthepop:K[:N]' (K: its queue length); 'supersample:N'
        means scalar with N x N samples; 'preset:NAME[:N]' a viewer preset (gbviewer.render.presets: its mode, view
        filter and SH bands); a suffix '+fast' or '+exact' sets the precision; '+lod' or '+lod:TAU' draws the
        level-of-detail cut at TAU pixels (default 1).

        The one parser of every surface that takes a mode (commands, viewer panes, the library): `options`
        (RenderSettings fields; None: not given) fill what the spec leaves unset, and one that disagrees with a part
        the spec sets is a one-line RenderError, never a silent override. `default_precision`: the precision where
        neither sets one (the surfaces that make pictures pass "fast"; measurements keep "exact")."""
        text = spec.label if isinstance(spec, Mode) else str(spec)
        parts = spec_parts(text)
        given = {k: v for k, v in options.items() if v is not None}
        settings = cls(**{"precision": default_precision, **given, **parts})
        for key in sorted(given.keys() & parts.keys()):
            ours = getattr(settings, key)
            theirs = getattr(replace(settings, preset="", **{key: given[key]}), key)  # the option as a field holds it
            if theirs != ours:
                what = key.replace("_", " ")
                raise RenderError(
                    f"mode {text!r} sets {what} {shown(ours)}; {what} {shown(theirs)} disagrees (give one of them)"
                )
        return settings

    @classmethod
    def parse_list(cls, specs: str, *, default_precision: str = "exact", **options) -> "list[RenderSettings]":
        """Comma-separated mode specs, each through `parse` with `options`, e.g. 'scalar,supersample:3,
        gaussian_blending': at least one, each once (SCALAR, scalar:1 and supersample:1 are scalar), none empty."""
        try:
            return distinct_items(
                specs,
                "--modes",
                lambda s: cls.parse(s, default_precision=default_precision, **options),
                key=lambda s: s.spec,
            )
        except InvalidValue as exc:
            raise RenderError(str(exc)) from None


def settings_from(
    mode: "str | Mode | RenderSettings",
    where: str,
    background: Sequence[float] = (0.0, 0.0, 0.0),
    debug: str = "none",
    **options,
) -> RenderSettings:
    """What a library call (`where`: render, trace_pixel) draws: `mode` a RenderSettings, which says everything
    (the call's other options then left at their defaults), else a spec `RenderSettings.parse` reads with them."""
    if isinstance(mode, RenderSettings):
        if any(v is not None for v in options.values()) or tuple(background) != (0.0, 0.0, 0.0) or debug != "none":
            raise RenderError(f"{where}: a RenderSettings says everything; give the options in it instead")
        return mode
    return RenderSettings.parse(mode, background=tuple(background), debug=debug, **options)


@dataclass
class FrameStats:
    """What a render measured, field by field (times in ms; None: not filled by this backend or mode).

    preprocess_ms, sort_ms, blend_ms: time per stage; total_ms: the whole render (a `render_many` frame's counts from
        the start of the call; on cpu its blend_ms is the time of the one tile loop all its frames share).
    visible: splats that survive preprocess.
    sort_length: keys sorted by depth (cpu: one per visible splat, the frame's global depth order, which it then bins
        in order; glsl and cuda: tile-splat pairs; duplex: tile-cell pairs; 0 for wsr, whose lists are only binned).
    sort_bytes: sort_length x SORT_ENTRY_BYTES.
    pairs: tile-list entries blended.
    evaluations: splat-pixel evaluations; evals_per_pixel: their mean per output pixel.
    backend: the backend's name; mode: `RenderSettings.label_for` the scene.
    simd: the SIMD path the cpu blend ran ("scalar", "avx2", "avx512", "neon"; GBVIEWER_SIMD at load or
        gbviewer._native.testing.set_simd); "scalar" for eval3d and stopthepop on every path (their per-pixel walk has
        no vector lanes).
    cells, cells_visible: duplex's cells and those drawn; cell_misses: splat-tile pairs outside their cell's tiles
        (not counted by glsl).
    decode_ms: the MLPs of a trained Duplex-GS model, per view.
    stage_reused (with `Capabilities.shared_stage`): whether the frame used a per-camera stage (the mode-independent
        preprocess; on cpu also the depth order) computed earlier, by another render or job of the same `render_many`.
    stage_ms: time spent building that stage in this frame (0 when reused; included in preprocess_ms).
    order_reused (cpu): whether the tile lists were binned in a depth order an earlier frame of that stage sorted
        (False where this frame sorted it, and for wsr and duplex, which bin without it).
    order_ms (cpu): time spent sorting the depth order in this frame (0 when reused; included in sort_ms, whose rest is
        the frame's own binning).
    lod_splats: the splats of the level-of-detail cut drawn (`RenderSettings.lod`).
    precision: the gaussian_blending kernel that ran ("exact" in every other mode, and on a backend without the fast
        one).
    """

    preprocess_ms: float = 0.0
    sort_ms: float = 0.0
    blend_ms: float = 0.0
    total_ms: float = 0.0
    visible: int = 0
    sort_length: int = 0
    sort_bytes: int = 0
    pairs: int = 0
    evaluations: int = 0
    evals_per_pixel: float = 0.0
    backend: str = ""
    mode: str = ""
    simd: str | None = None
    cells: int | None = None
    cells_visible: int | None = None
    cell_misses: int | None = None
    decode_ms: float | None = None
    stage_reused: bool | None = None
    order_reused: bool | None = None
    stage_ms: float | None = None
    order_ms: float | None = None
    lod_splats: int | None = None
    precision: str = "exact"


@dataclass(eq=False)
class Frame:
    """A rendered image: rgb (H,W,3) float32, alpha = 1 - final transmittance (H,W), debug planes, stats.

    debug: "evals" (H,W) splats evaluated per output pixel (summed over sub-samples); "window" (H,W,2) when
    requested.
    """

    rgb: np.ndarray
    alpha: np.ndarray
    stats: FrameStats = field(default_factory=FrameStats)
    debug: dict[str, np.ndarray] = field(default_factory=dict)
