"""The benchmark's loop: views per scene, then speed, fidelity, flicker (temporal stability) and (with wsr or
duplex) the order-independent measures of every scene, with one progress bar per scene."""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from ..core.errors import GBViewerError
from ..core.files import check_writable
from ..core.validate import integer
from ..io import load
from ..model.camera import Camera, load_cameras_json, orbit_camera
from ..model.scene import Scene
from ..render import BACKENDS, Mode, RenderSettings
from .fidelity import FidelityRow, fidelity_cost, measure_fidelity
from .oit import OitRow, measure_oit, oit_cost
from .simd import parse_simd, simd_info
from .speed import SpeedRow, measure_speed, speed_cost
from .stability import FlickerRow, measure_stability, stability_cost

# progress(scene name, total render_cost units) -> a context that yields advance(units)
Progress = Callable[[str, float], AbstractContextManager[Callable[[float], None]]]


@dataclass
class BenchResult:
    """Every row of a run, and simd_info() of the CPU backend (None without it)."""

    speed: list[SpeedRow] = field(default_factory=list)
    fidelity: list[FidelityRow] = field(default_factory=list)
    oit: list[OitRow] = field(default_factory=list)
    simd: dict | None = None
    flicker: list[FlickerRow] = field(default_factory=list)


def bench_views(
    scene: Scene, views: int, width: int, height: int, cameras: Path | None = None, up: str = "-y", multiple: int = 1
) -> list[Camera]:
    """Training cameras (resized to width x height) when given, else `views` orbit views around the robust bounds.
    The size is rounded down to a multiple of `multiple` (the largest zoom factor), so that every box-downsampled
    reference covers exactly the pixels of the low-rate render."""
    width, height = max(multiple, width // multiple * multiple), max(multiple, height // multiple * multiple)
    if cameras is not None:
        cams = load_cameras_json(cameras)
        step = max(1, len(cams) // views)
        return [c.with_size(width, height) for c in cams[::step][:views]]
    return [orbit_camera(scene, 360.0 * i / views, 20.0, width=width, height=height, up=up) for i in range(views)]


def select_backends(names: Sequence[str]) -> tuple[list[str], dict[str, str]]:
    """The backends of `names` that run here, and why each other one does not; an unknown name is an error."""
    unknown = [b for b in names if b not in BACKENDS]
    if unknown:
        raise GBViewerError(f"unknown backend(s) {unknown}; expected some of {', '.join(BACKENDS)}")
    why = {b: BACKENDS[b].available()[1] for b in dict.fromkeys(names) if not BACKENDS[b].available()[0]}
    return [b for b in names if b not in why], why


def run_bench(
    scenes: Sequence[Path],
    settings: list[RenderSettings],
    rates: list[float],
    backends: list[str],
    *,
    views: int,
    size: tuple[int, int],
    repeat: int,
    cameras: Path | None = None,
    up: str = "-y",
    simd: str | None = None,
    flicker_frames: int = 16,
    flicker_step: float = 0.1,
    flicker_pairs: int = 3,
    flicker_size: tuple[int, int] = (160, 120),
    outputs: Sequence[Path] = (),
    force: bool = False,
    progress: Progress | None = None,
) -> BenchResult:
    """Speed on every backend (the CPU backend on each SIMD path of `simd`, see parse_simd), fidelity on the first
    backend, flicker (`stability`; `flicker_pairs` pairs at `flicker_size`, 0 pairs: none) on the first backend,
    and with wsr or duplex among `settings` the order-independent measures, for every scene file.
    `outputs`: files the caller writes afterwards, checked (`check_writable`) before anything is measured."""
    if not backends:
        raise GBViewerError("no backend available")
    if not rates:
        raise GBViewerError("--rates: no sampling rate given")
    views, repeat = integer(views, "--views", lo=1), integer(repeat, "--repeat", lo=1)
    for out in outputs:
        check_writable(out, force)
    result = BenchResult()
    paths, exp = None, None
    if any(BACKENDS[b].capabilities.simd for b in backends):
        paths = parse_simd(simd)
        result.simd = simd_info(paths)
        exp = result.simd["exp_per_s_per_core"]
    with_oit = any(s.mode in (Mode.WSR, Mode.DUPLEX) for s in settings)
    multiple = max(round(1 / r) if r < 1 else round(r) for r in rates)  # the largest zoom factor
    for path in scenes:
        scene = load(path)
        name = Path(path).name
        cams = bench_views(scene, views, *size, cameras, up, multiple)
        total = (
            speed_cost(scene, cams, settings, backends, rates, repeat, paths)
            + fidelity_cost(scene, cams, settings, rates)
            + (stability_cost(scene, cams[0], settings, flicker_pairs, flicker_size) if flicker_pairs else 0)
            + (oit_cost(scene, cams, settings, flicker_frames) if with_oit else 0)
        )
        with progress(name, total) if progress else nullcontext() as step:
            result.speed += measure_speed(scene, name, cams, settings, backends, rates, repeat, step, paths, exp)
            result.fidelity += measure_fidelity(scene, name, cams, settings, rates, backends[0], step)
            if flicker_pairs:
                result.flicker += measure_stability(
                    scene, name, cams[0], settings, flicker_pairs, flicker_size, backends[0], step
                )
            if with_oit:
                result.oit += measure_oit(
                    scene, name, cams, settings, backends[0], flicker_frames, flicker_step, up, step
                )
    return result
