"""Temporal stability in the benchmark: every mode's flicker (gbviewer.outputs.flicker) along a zoom-out from the first
bench view, small and short so that it stays cheap, with the floor of the supersampled reference."""

from __future__ import annotations

from dataclasses import dataclass

from ..model.camera import Camera
from ..model.scene import Scene
from ..outputs.flicker import DEFAULT_REFERENCE, flicker_path, floor_settings, measure_flicker, pair_starts
from ..render import RenderSettings
from .speed import render_cost

ZOOM = (1.0, 0.25)  # the path: x1 to x1/4 over FRAMES frames (4 s at 30 fps, as gbviewer video's default)
FRAMES = 120


@dataclass
class FlickerRow:
    """One mode's flicker and change (8-bit levels, see gbviewer.outputs.flicker) on one scene; floor: the reference at
    half its samples per axis against it, the smallest flicker the measure resolves."""

    scene: str
    mode: str
    label: str
    width: int
    height: int
    pairs: int
    reference: str
    flicker: float
    change: float
    floor: float | None


def _reference() -> RenderSettings:
    return RenderSettings.parse(DEFAULT_REFERENCE)


def stability_cost(
    scene: Scene, cam: Camera, settings: list[RenderSettings], pairs: int, size: tuple[int, int]
) -> float:
    """The render_cost units measure_stability reports: each distinct settings (the modes, the reference, the
    floor) on each frame of the pairs."""
    c = cam.with_size(*size)
    starts = pair_starts(FRAMES, pairs)
    frames = len(set(starts) | {i + 1 for i in starts})
    floor = floor_settings(_reference())
    measured = dict.fromkeys([*settings, _reference(), *([floor] if floor is not None else [])])
    return frames * sum(render_cost(c, s, scene.num_splats) for s in measured)


def measure_stability(
    scene: Scene,
    name: str,
    cam: Camera,
    settings: list[RenderSettings],
    pairs: int,
    size: tuple[int, int],
    backend: str = "cpu",
    progress=None,
) -> list[FlickerRow]:
    """Flicker of every mode over `pairs` pairs of the zoom ZOOM (FRAMES frames) from `cam` at `size`.
    progress(units) is called with render_cost units as renders finish."""
    c = cam.with_size(*size)
    path = flicker_path("zoom", c, scene, FRAMES, *ZOOM)
    n = scene.num_splats
    step = None if progress is None else (lambda s: progress(render_cost(c, s, n)))
    rep = measure_flicker(
        scene, path, settings, reference=_reference(), pairs=pairs, backend=backend, path_name="zoom", progress=step
    )
    floor = rep.floor.flicker if rep.floor is not None else None
    return [
        FlickerRow(name, m.spec, m.label, c.width, c.height, len(rep.starts), rep.reference, m.flicker, m.change, floor)
        for m in rep.modes
    ]
