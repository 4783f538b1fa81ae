"""Zoom fidelity: PSNR and SSIM of each mode against box-downsampled references (zoom-out: the x1 scalar render;
zoom-in: the mode's own x1 render)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.camera import Camera
from ..model.scene import Scene
from ..outputs.metrics import box_downsample, psnr, ssim, zoom_factor
from ..render import Mode, RenderSettings, get_renderer
from .speed import render_cost


@dataclass
class FidelityRow:
    scene: str
    mode: str
    rate: float
    kind: str  # "zoom-out" (vs x1 scalar, box-downsampled) or "zoom-in" (downsampled vs x1 of the same mode)
    psnr: float
    ssim: float
    simd: str | None = None  # the CPU backend's path that rendered it (Frame.stats.simd); None on other backends


def _referenced(rates: list[float]) -> list[float]:
    """The rates other than 1 that have a box-downsampled reference: 1/k and k for integers k."""
    return [rate for rate in rates if rate != 1 and zoom_factor(rate) is not None]


def measure_fidelity(
    scene: Scene,
    name: str,
    cams: list[Camera],
    settings: list[RenderSettings],
    rates: list[float],
    backend: str = "cpu",
    progress=None,
) -> list[FidelityRow]:
    """Zoom-out: each mode at rate 1/k against the x1 scalar render box-downsampled by k.
    Zoom-in: each mode at rate k box-downsampled by k against the x1 render of the same mode. On the CPU backend
    with the SIMD path in use. progress(units) is called with render_cost units as renders finish."""
    renderer = get_renderer(scene, backend)
    acc: dict[tuple[str, float, str], list[tuple[float, float]]] = {}
    ran: dict[tuple[str, float, str], str | None] = {}
    for cam in cams:
        ref_scalar = renderer.render(cam, RenderSettings(Mode.SCALAR)).rgb
        if progress:
            progress(render_cost(cam, RenderSettings(Mode.SCALAR), scene.num_splats))
        for s in settings:
            ref_same = renderer.render(cam, s).rgb
            if progress:
                progress(render_cost(cam, s, scene.num_splats))
            for rate in _referenced(rates):
                k = zoom_factor(rate)
                c = cam.at_sampling_rate(rate)
                f = renderer.render(c, s)
                img = f.rgb
                if rate < 1:
                    ref, kind = box_downsample(ref_scalar, k), "zoom-out"
                else:
                    img, ref, kind = box_downsample(img, k), ref_same, "zoom-in"
                acc.setdefault((s.spec, rate, kind), []).append((psnr(img, ref), ssim(img, ref)))
                ran[s.spec, rate, kind] = f.stats.simd
                if progress:
                    progress(render_cost(c, s, scene.num_splats))
    return [
        FidelityRow(
            name,
            spec,
            rate,
            kind,
            float(np.mean([p for p, _ in v])),
            float(np.mean([q for _, q in v])),
            ran[spec, rate, kind],
        )
        for (spec, rate, kind), v in acc.items()
    ]


def fidelity_cost(scene: Scene, cams: list[Camera], settings: list[RenderSettings], rates: list[float]) -> float:
    """The render_cost units measure_fidelity reports."""
    total = 0.0
    for cam in cams:
        total += render_cost(cam, RenderSettings(Mode.SCALAR), scene.num_splats)
        for s in settings:
            total += render_cost(cam, s, scene.num_splats)
            total += sum(render_cost(cam.at_sampling_rate(rate), s, scene.num_splats) for rate in _referenced(rates))
    return total
