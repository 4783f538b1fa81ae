"""Shimmer as a number: the temporal stability of each mode along a camera path, compensated for the camera's motion
by a dense reference.

For pairs of consecutive frames (t, t+1) of a path (the frames `gbviewer video` renders, or a slow orbit), with
images clipped to [0, 1] and shown at the pane size (rate sweeps nearest-resized, as in the video):

    change_m(x)  = I_m(t+1, x) - I_m(t, x)                         (what the viewer sees move)
    flicker_m(x) = 255 * mean over RGB of |change_m(x) - change_R(x)|  (8-bit levels)

R is the reference: scalar with 8 x 8 supersampling (`DEFAULT_REFERENCE`). The camera's true motion changes R and
every well-sampled mode alike, so it cancels in the difference and needs no depth (the renderers output none) nor
any warping; what remains is the change the mode adds of its own: aliasing that comes and goes as splats cross
pixel centres. It is exactly 0 for a static camera and for R itself, and equals 0 for a scene the mode samples
as well as R. Summary per mode: the mean over pairs and pixels (`ModeFlicker.flicker`); heat map: the mean over
pairs per pixel (`ModeFlicker.heat`).

The floor is what the measure cannot resolve: R at half its samples per axis measured against R (scalar 4x4
against 8x8); R's own residual is below it. The default R pops as scalar does (one global order by centre depth), so
that popping cancels; R = stopthepop:0:8 (the exact per-pixel order) is popping-free and charges it to the mode.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from PIL import Image

from ..core.errors import GBViewerError
from ..core.files import atomic_write
from ..core.validate import dumps_json, integer, real
from ..model.camera import UP_AXES, Camera, format_rate
from ..model.camera_paths import MAX_FRAMES, PATHS, PathFrame, camera_path, path_length
from ..model.scene import Scene
from ..render import FrameStats, Mode, RenderSettings, get_renderer
from ..render.modes import STOCHASTIC_MODES
from .differences import diverging, robust_scale
from .figure import GAP, Cell, compose_grid, save_image, upscale_nearest
from .video import write_video

FLICKER_PATHS = (*PATHS, "orbit")
DEFAULT_REFERENCE = "supersample:8"
DEFAULT_DEGREES = 12.0  # azimuth swept by the orbit path (over 120 frames: 0.1 degree per frame)
DEFAULT_PAIRS = 8
VIEW_STEP = 0.1  # degrees of the viewer's flicker view: the orbit path's default step per frame
MIN_HEAT_SCALE = 1.0  # 8-bit levels: the colour scale of heat maps that are all ~0
CSV_COLUMNS = ("mode", "label", "flicker", "change", "vs_floor", "reference", "floor", "pairs", "frames", "path")


@dataclass(eq=False)
class ModeFlicker:
    """One mode's measure: flicker and change in 8-bit levels (means over pairs, pixels and channels), heat (H, W)
    the per-pixel flicker averaged over pairs; per_pair: each pair's map (float16), kept for the heat-map video."""

    spec: str
    label: str
    flicker: float
    change: float
    heat: np.ndarray
    per_pair: list[np.ndarray] = field(default_factory=list)


@dataclass
class FlickerReport:
    """Every mode's measure along one path, the reference's own change and the floor (None where the reference
    has no half-rate version)."""

    path: str
    frames: int
    starts: list[int]  # the first frame of every pair
    reference: str
    reference_change: float
    modes: list[ModeFlicker]
    floor: ModeFlicker | None

    def rows(self) -> list[dict]:
        """One dict per mode (CSV_COLUMNS); vs_floor: flicker / floor (None without a floor)."""
        floor = self.floor.flicker if self.floor is not None else None
        return [
            {
                "mode": m.spec,
                "label": m.label,
                "flicker": m.flicker,
                "change": m.change,
                "vs_floor": m.flicker / floor if floor else None,
                "reference": self.reference,
                "floor": floor,
                "pairs": len(self.starts),
                "frames": self.frames,
                "path": self.path,
            }
            for m in self.modes
        ]

    def to_json(self) -> dict:
        return {
            "path": self.path,
            "frames": self.frames,
            "pair_starts": self.starts,
            "reference": self.reference,
            "reference_change": self.reference_change,
            "floor": None if self.floor is None else {"mode": self.floor.spec, "flicker": self.floor.flicker},
            "modes": self.rows(),
        }


def orbit_path(
    base: Camera, scene: Scene, frames: int, degrees: float = DEFAULT_DEGREES, up: str = "-y"
) -> list[PathFrame]:
    """The base camera turned about the `up` axis through the centre of the scene's robust bounds, `degrees` of
    azimuth from the first frame to the last (both included), at rate 1."""
    frames = integer(frames, "frames of the path", lo=1)
    degrees = real(degrees, "orbit degrees", lo=-360.0, hi=360.0)
    lo, hi = scene.robust_bounds()
    c = (np.asarray(lo, np.float64) + hi) / 2
    u = np.asarray(UP_AXES[up], np.float64)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    out = []
    for i in range(frames):
        a = np.radians(degrees * (i / (frames - 1) if frames > 1 else 0.0))
        q = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)  # Rodrigues: the world turned by a about u
        R = base.R @ q.T
        cam = replace(base, R=R, t=base.t + base.R @ c - R @ c)
        out.append(PathFrame.of(cam))
    return out


def flicker_path(
    kind: str | Path,
    base: Camera,
    scene: Scene,
    frames: int | None = None,
    start: float = 1.0,
    end: float = 1.0 / 8.0,
    *,
    degrees: float = DEFAULT_DEGREES,
    up: str = "-y",
    fps: float = 30.0,
    seconds: float | None = None,
    max_frames: int = MAX_FRAMES,
) -> list[PathFrame]:
    """'orbit' (`orbit_path`), or any path `camera_paths.camera_path` makes (zoom, dolly, rate, keyframes FILE),
    of the length `gbviewer video` gives it (`frames`, or seconds x fps, or 4 s)."""
    if str(kind) != "orbit":
        return camera_path(kind, base, frames, start, end, scene, up, fps=fps, seconds=seconds, max_frames=max_frames)
    return orbit_path(
        base,
        scene,
        path_length(frames, real(fps, "fps", lo=0.0, lo_open=True), seconds, max_frames=max_frames),
        degrees,
        up,
    )


def pair_starts(frames: int, pairs: int) -> list[int]:
    """First frames of `pairs` pairs of consecutive frames spread evenly over a path of `frames` frames (fewer when
    the path has fewer than pairs + 1 frames); an error for a path of one frame."""
    frames, pairs = integer(frames, "frames of the path", lo=1), integer(pairs, "--pairs", lo=1)
    if frames < 2:
        raise GBViewerError("the path has 1 frame; flicker needs at least 2 (pairs of consecutive frames)")
    return sorted({round(x) for x in np.linspace(0, frames - 2, min(pairs, frames - 1))})


def floor_settings(reference: RenderSettings) -> RenderSettings | None:
    """The reference at half its samples per axis (None for a reference of one sample)."""
    return replace(reference, supersample=reference.supersample // 2) if reference.supersample > 1 else None


def pane_image(renderer, pf: PathFrame, settings: RenderSettings, cancel=None, accumulate: int = 1) -> np.ndarray:
    """One frame of the path as shown: rgb clipped to [0, 1], nearest-resized to the pane, float32. A stochastic
    mode shows the mean of `accumulate` frame indices from its own (as a still viewer pane after that many frames)."""
    k = integer(accumulate, "--accumulate", lo=1) if settings.mode in STOCHASTIC_MODES else 1
    rgb = renderer.render(pf.camera, settings, cancel=cancel).rgb
    if k > 1:
        rgb = np.mean(
            [
                rgb,
                *(
                    renderer.render(pf.camera, replace(settings, frame=settings.frame + f), cancel=cancel).rgb
                    for f in range(1, k)
                ),
            ],
            axis=0,
        )
    rgb = np.clip(rgb, 0.0, 1.0)
    if rgb.shape[:2] != (pf.height, pf.width):
        rgb = upscale_nearest(rgb, pf.height, pf.width)
    return rgb.astype(np.float32, copy=False)


def measure_flicker(
    scene: Scene,
    path: Sequence[PathFrame],
    settings: Sequence[RenderSettings],
    *,
    reference: RenderSettings | None = None,
    pairs: int = DEFAULT_PAIRS,
    backend: str = "cpu",
    with_floor: bool = True,
    keep_pairs: bool = False,
    path_name: str = "",
    progress: Callable[[RenderSettings], None] | None = None,
    renderer=None,
    cancel=None,
    accumulate: int = 1,
) -> FlickerReport:
    """Flicker and change of every mode of `settings` over `pairs` pairs of consecutive frames of `path` (see the
    module's docstring), against `reference` (default scalar 8x8), with the floor unless `with_floor` is False.
    keep_pairs: keep each pair's heat map (for `write_heat_video`). progress(settings) after each render.
    renderer: render on it (else the process's renderer of `backend`); cancel: passed to every render.
    accumulate: each stochastic mode's frame is the mean of that many frame indices (`pane_image`)."""
    reference = reference or RenderSettings.parse(DEFAULT_REFERENCE)
    if not settings:
        raise GBViewerError("no modes given")
    if any((pf.width, pf.height) != (path[0].width, path[0].height) for pf in path):
        raise GBViewerError("every frame of the camera path must have the same pane size")
    starts = pair_starts(len(path), pairs)
    floor = floor_settings(reference) if with_floor else None
    measured = list(dict.fromkeys([*settings, *([floor] if floor is not None else [])]))
    renderer = renderer or get_renderer(scene, backend)
    cache: dict[tuple[RenderSettings, int], np.ndarray] = {}

    def image(s: RenderSettings, i: int) -> np.ndarray:
        if (s, i) not in cache:
            cache[s, i] = pane_image(renderer, path[i], s, cancel, accumulate)
            if progress is not None:
                progress(s)
        return cache[s, i]

    h, w = path[0].height, path[0].width
    heat = {s: np.zeros((h, w), np.float64) for s in measured}
    change = {s: 0.0 for s in [reference, *measured]}
    per_pair: dict[RenderSettings, list[np.ndarray]] = {s: [] for s in measured}
    for i in starts:
        for key in [k for k in cache if k[1] < i]:
            del cache[key]  # only the pair's frames (the next pair may start on this one's second)
        d_ref = image(reference, i + 1) - image(reference, i)
        change[reference] += float(np.abs(d_ref).mean())
        for s in measured:
            d = d_ref if s == reference else image(s, i + 1) - image(s, i)
            e = 255.0 * np.abs(d - d_ref).mean(axis=2)
            heat[s] += e
            change[s] += float(np.abs(d).mean())
            if keep_pairs:
                per_pair[s].append(e.astype(np.float16))
    n = len(starts)
    results = {
        s: ModeFlicker(
            s.spec,
            s.label_for(scene),
            float(heat[s].mean() / n),
            255.0 * change[s] / n,
            (heat[s] / n).astype(np.float32),
            per_pair[s],
        )
        for s in measured
    }
    return FlickerReport(
        path_name,
        len(path),
        starts,
        reference.spec,
        255.0 * change[reference] / n,
        [results[s] for s in settings],
        results[floor] if floor is not None else None,
    )


def view_flicker(
    renderer, scene: Scene, camera: Camera, settings: RenderSettings, degrees: float = VIEW_STEP, cancel=None
) -> ModeFlicker:
    """The flicker of one orbit step of `degrees` from `camera` in `settings` against the default reference (the
    viewer's flicker view), on `renderer`."""
    return measure_flicker(
        scene,
        orbit_path(camera, scene, 2, degrees),
        [settings],
        pairs=1,
        with_floor=False,
        renderer=renderer,
        cancel=cancel,
    ).modes[0]


def heat_colours(heat: np.ndarray, scale: float) -> np.ndarray:
    """A heat map (8-bit levels >= 0) as RGB in [0, 1]: near-black at 0 to light red at `scale` and above (the
    positive half of the difference views' diverging map)."""
    return diverging(np.asarray(heat, np.float32) / max(float(scale), 1e-12))


def heat_scale(maps: Sequence[np.ndarray]) -> float:
    """One colour scale for several heat maps: the largest of their 99th percentiles, at least MIN_HEAT_SCALE."""
    return max([MIN_HEAT_SCALE] + [robust_scale(m, 99.0) for m in maps])


def heat_file(out_dir: str | Path, spec: str) -> Path:
    """Where `write_heat_maps` puts the heat map of mode `spec`: OUT_DIR/heat-SPEC.png (':' and the like as '_')."""
    return Path(out_dir) / f"heat-{re.sub(r'[^A-Za-z0-9.+-]+', '_', spec)}.png"


def _cell(m: ModeFlicker, rgb: np.ndarray) -> Cell:
    return Cell(RenderSettings(Mode.SCALAR), 1.0, rgb, FrameStats(mode=m.label))


def heat_figure(m: ModeFlicker, scale: float, reference: str) -> Image.Image:
    """A mode's heat map captioned below with its label, flicker and change, and the colour scale."""
    h, w = m.heat.shape
    lines = [
        m.label,
        f"flicker {m.flicker:.3f}, change {m.change:.3f} levels",
        f"vs {reference}; black 0 .. red {scale:.3g} levels",
    ]
    return compose_grid([[_cell(m, heat_colours(m.heat, scale))]], w, h, GAP, captions="below", lines=lambda _: lines)


def write_heat_maps(out_dir: str | Path, report: FlickerReport, force: bool = False) -> list[Path]:
    """Every mode's `heat_figure` (one colour scale for all) as heat-SPEC.png in `out_dir`, atomically."""
    scale = heat_scale([m.heat for m in report.modes])
    return [
        save_image(heat_file(out_dir, m.spec), heat_figure(m, scale, report.reference), force) for m in report.modes
    ]


def write_heat_video(
    out: str | Path, report: FlickerReport, path: Sequence[PathFrame], fps: float = 30.0, force: bool = False
) -> Path:
    """The per-pair heat maps of every mode side by side, one video frame per pair, captioned with the mode and
    the pair (needs measure_flicker(keep_pairs=True)); one colour scale for the whole video."""
    if not report.modes or not report.modes[0].per_pair:
        raise GBViewerError("heat-map video: the measure kept no per-pair maps (keep_pairs=True)")
    scale = heat_scale([np.asarray(e, np.float32) for m in report.modes for e in m.per_pair])
    h, w = report.modes[0].heat.shape

    def images():
        for k, i in enumerate(report.starts):
            cells = [_cell(m, heat_colours(m.per_pair[k], scale)) for m in report.modes]
            caption = f"frames {i}-{i + 1}, rate {format_rate(path[i].rate)}, red {scale:.3g} levels"
            yield np.asarray(
                compose_grid(
                    [cells],
                    w,
                    h,
                    GAP,
                    captions="below",
                    even=True,
                    lines=lambda c, caption=caption: [c.mode_label, caption],
                )
            )

    write_video(out, images(), len(report.starts), fps=fps, force=force)
    return Path(out)


def write_table(out_dir: str | Path, report: FlickerReport, force: bool = False) -> list[Path]:
    """flicker.csv (CSV_COLUMNS, one row per mode) and flicker.json (FlickerReport.to_json) in `out_dir`."""
    out_dir = Path(out_dir)

    def write_csv(p: Path) -> None:
        with open(p, "w", newline="") as fh:
            writer = csv.DictWriter(fh, CSV_COLUMNS)
            writer.writeheader()
            writer.writerows({k: ("" if v is None else v) for k, v in row.items()} for row in report.rows())

    return [
        atomic_write(out_dir / "flicker.csv", write_csv, force),
        atomic_write(out_dir / "flicker.json", lambda p: p.write_text(dumps_json(report.to_json(), indent=2)), force),
    ]
