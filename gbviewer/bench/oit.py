"""Sorted scalar blending against the order-independent modes (wsr, duplex): sort length, cells, PSNR against
scalar, and flicker along a slow orbit."""

from __future__ import annotations

import statistics
from dataclasses import dataclass

import numpy as np

from ..model.camera import Camera, orbit_camera
from ..model.scene import Scene
from ..outputs.metrics import flicker, psnr
from ..render import Mode, RenderSettings, get_renderer
from .speed import STAGES, render_cost


@dataclass
class OitRow:
    """Sorted scalar blending against the order-independent modes on one scene (means over the bench views).

    sort_length: keys ordered by depth per frame (tile-splat pairs for scalar, 0 for wsr, tile-cell pairs for
    duplex: the paper's Table VI quantity), sort_mb: their memory (render.SORT_ENTRY_BYTES each), pairs: tile-list
    entries the blend walks, visible: splats that survive preprocess, cells / cells_visible: duplex cells in the
    scene / in the view (cells vs splats), stages_ms: median per stage, psnr_vs_scalar: against the sorted scalar
    render of the same view, flicker / pops: see `flicker`."""

    scene: str
    backend: str
    mode: str
    label: str
    width: int
    height: int
    visible: int
    sort_length: int
    sort_mb: float
    pairs: int
    cells: int
    cells_visible: int
    cell_misses: int
    stages_ms: dict
    psnr_vs_scalar: float
    flicker: float
    pops: float


def oit_settings(settings: list[RenderSettings]) -> dict[Mode, RenderSettings]:
    """What measure_oit renders: scalar (the reference) and the first wsr and duplex of `settings` at 1 sample per
    pixel."""
    wanted = {Mode.SCALAR: RenderSettings(Mode.SCALAR)}
    for s in settings:
        if s.mode in (Mode.WSR, Mode.DUPLEX) and s.supersample == 1:
            wanted.setdefault(s.mode, s)
    return wanted


def oit_cost(scene: Scene, cams: list[Camera], settings: list[RenderSettings], flicker_frames: int = 16) -> float:
    """The render_cost units measure_oit reports."""
    wanted = oit_settings(settings)
    return sum(
        sum(
            2 * render_cost(c, s, scene.num_splats) + render_cost(c, wanted[Mode.SCALAR], scene.num_splats)
            for c in cams
        )
        + flicker_frames * render_cost(cams[0], s, scene.num_splats)
        for s in wanted.values()
    )


def measure_oit(
    scene: Scene,
    name: str,
    cams: list[Camera],
    settings: list[RenderSettings],
    backend: str = "cpu",
    flicker_frames: int = 16,
    flicker_step: float = 0.1,
    up: str = "-y",
    progress=None,
) -> list[OitRow]:
    """scalar, wsr and duplex (those of `settings` at 1 sample per pixel, plus scalar as the reference) on the bench
    views, and the flicker of each along an orbit of `flicker_frames` frames, `flicker_step` degrees apart.
    progress(units) is called with render_cost units as renders finish (oit_cost() in all)."""
    wanted = oit_settings(settings)
    renderer = get_renderer(scene, backend)
    rows = []
    for _mode, s in wanted.items():
        acc: dict[str, list] = {}
        last = None
        for cam in cams:
            ref = renderer.render(cam, RenderSettings(Mode.SCALAR)).rgb
            renderer.render(cam, s)  # warm-up (duplex: builds the cells once)
            f = renderer.render(cam, s)
            last = f.stats
            for k in STAGES + (
                "visible",
                "sort_length",
                "sort_bytes",
                "pairs",
                "cells",
                "cells_visible",
                "cell_misses",
            ):
                acc.setdefault(k, []).append(getattr(f.stats, k) or 0)
            acc.setdefault("psnr", []).append(psnr(f.rgb, ref))
            if progress:
                progress(
                    2 * render_cost(cam, s, scene.num_splats) + render_cost(cam, wanted[Mode.SCALAR], scene.num_splats)
                )
        c0 = cams[0]
        frames = [
            renderer.render(
                orbit_camera(scene, 30.0 + i * flicker_step, 20.0, width=c0.width, height=c0.height, up=up), s
            ).rgb
            for i in range(flicker_frames)
        ]
        if progress:
            progress(flicker_frames * render_cost(c0, s, scene.num_splats))
        fl, pops = flicker(frames)
        mean = {k: float(np.mean(v)) for k, v in acc.items()}
        rows.append(
            OitRow(
                name,
                backend,
                s.spec,
                last.mode,
                c0.width,
                c0.height,
                round(mean["visible"]),
                round(mean["sort_length"]),
                mean["sort_bytes"] / 2**20,
                round(mean["pairs"]),
                round(mean["cells"]),
                round(mean["cells_visible"]),
                round(mean["cell_misses"]),
                {k: float(statistics.median(acc[k])) for k in STAGES},
                mean["psnr"],
                fl,
                pops,
            )
        )
    return rows
