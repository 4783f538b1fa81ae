"""Speed per backend, SIMD path, mode and sampling rate: frame and stage times, evaluation rates, the ratios between
modes and between SIMD paths; `render_cost`, the unit of the progress bars."""

from __future__ import annotations

import os
import statistics
from dataclasses import dataclass

import numpy as np

from ..model.camera import Camera
from ..model.scene import Scene
from ..render import BACKENDS, Mode, RenderSettings, get_renderer
from .simd import current_simd, set_simd

STAGES = ("preprocess_ms", "sort_ms", "blend_ms", "total_ms")
MODE_COST = {Mode.ANALYTIC: 8.0, Mode.GAUSSIAN_BLENDING: 3.0}  # rough cost per sample against scalar, for the ETA


def render_cost(cam: Camera, s: RenderSettings, splats: int) -> float:
    """A rough work estimate of one render (samples + splats, times a mode factor): the progress bar's unit."""
    return (cam.width * cam.height * s.supersample**2 + splats) * MODE_COST.get(s.mode, 1.0)


@dataclass
class SpeedRow:
    """One backend, SIMD path, mode and rate on one scene: median, min and max of the frame time over repeats and
    views, median per stage, evaluations per pixel (mean over views) and the evaluation rates (all the timed
    renders' evaluations over all their time).

    simd: the path the CPU backend's blend ran (Frame.stats.simd; None on other backends), simd_requested: the
    path set for the measurement (the two differ where a mode has no vector code). mevals_per_s_per_core:
    splat-pixel evaluations per second of frame time per core; blend_mevals_per_s_per_core: the same over the
    blend stage alone, to compare with exp_mevals_per_s_per_core, the exp throughput of one core on that path.
    simd_max_abs_diff: the largest |rgb - rgb of the scalar path| over the same views (None for scalar itself or
    when scalar is not measured)."""

    scene: str
    backend: str
    mode: str
    rate: float
    width: int
    height: int
    median_ms: float
    min_ms: float
    max_ms: float
    stages_ms: dict
    visible: int
    sort_length: int
    evals_per_pixel: float
    mevals_per_s_per_core: float
    simd: str | None = None
    simd_requested: str | None = None
    blend_mevals_per_s_per_core: float = 0.0
    exp_mevals_per_s_per_core: float | None = None
    simd_max_abs_diff: float | None = None


def measure_speed(
    scene: Scene,
    name: str,
    cams: list[Camera],
    settings: list[RenderSettings],
    backends: list[str],
    rates: list[float],
    repeat: int,
    progress=None,
    simd: list[str] | None = None,
    exp: dict[str, float] | None = None,
) -> list[SpeedRow]:
    """Median over `repeat` renders of every view, per backend, SIMD path, mode and rate (one warm-up render per
    path, mode and rate before the first view).

    simd: the CPU backend's paths to measure (None: the one in use). They take turns render by render (each
    repeat of a view on every path, then the next), so that a change in the machine's load falls on all of them
    alike; the path in use before is restored at the end. exp: exp_rates(), for exp_mevals_per_s_per_core.
    progress(units) is called with render_cost units as renders finish (speed_cost() in all)."""
    rows = []
    cores = os.cpu_count() or 1
    for backend in backends:
        renderer = get_renderer(scene, backend)
        caps = BACKENDS[backend].capabilities
        before = active = current_simd() if caps.simd else None
        paths: list[str | None] = list(dict.fromkeys(simd)) if caps.simd and simd else [before]
        per_core = cores if caps.host else 1
        try:
            for rate in rates:
                for s in settings:
                    acc = {
                        p: {"totals": [], "stages": {k: [] for k in STAGES}, "evals": [], "last": None, "diff": None}
                        for p in paths
                    }
                    for i, cam in enumerate(cams):
                        c = cam.at_sampling_rate(rate)
                        cost = render_cost(c, s, scene.num_splats)
                        images = {}
                        for rep in range(-1 if i == 0 else 0, repeat):  # -1: the warm-up
                            for path in paths:
                                if path != active:
                                    set_simd(path)
                                    active = path
                                f = renderer.render(c, s)
                                if progress:
                                    progress(cost)
                                if rep < 0:
                                    continue  # first-touch allocations, caches, the new path
                                a = acc[path]
                                a["last"] = f.stats
                                a["totals"].append(f.stats.total_ms)
                                a["evals"].append(f.stats.evals_per_pixel)
                                for k in STAGES:
                                    a["stages"][k].append(getattr(f.stats, k))
                                images[path] = f.rgb
                        if "scalar" in images:  # the vector paths against the scalar one, same view
                            for path, img in images.items():
                                if path != "scalar":
                                    d = float(np.abs(img - images["scalar"]).max())
                                    acc[path]["diff"] = d if acc[path]["diff"] is None else max(acc[path]["diff"], d)
                    for path in paths:
                        a = acc[path]
                        last, totals = a["last"], a["totals"]
                        med = {k: statistics.median(v) for k, v in a["stages"].items()}
                        # evaluation rates: all the timed renders' evaluations over all their time (views differ)
                        evals = sum(a["evals"]) * c.width * c.height
                        ran = last.simd if caps.simd else None
                        rows.append(
                            SpeedRow(
                                name,
                                backend,
                                s.spec,
                                rate,
                                c.width,
                                c.height,
                                statistics.median(totals),
                                min(totals),
                                max(totals),
                                med,
                                last.visible,
                                last.sort_length,
                                float(np.mean(a["evals"])),
                                evals / max(sum(totals), 1e-9) / 1e3 / per_core,
                                ran,
                                path,
                                evals / max(sum(a["stages"]["blend_ms"]), 1e-9) / 1e3 / per_core,
                                exp[ran] / 1e6 if exp and ran in exp else None,
                                a["diff"],
                            )
                        )
        finally:
            if caps.simd and current_simd() != before:
                set_simd(before)
    return rows


def speed_cost(
    scene: Scene,
    cams: list[Camera],
    settings: list[RenderSettings],
    backends: list[str],
    rates: list[float],
    repeat: int,
    simd: list[str] | None = None,
) -> float:
    """The render_cost units measure_speed reports."""
    per_backend = sum(
        render_cost(cam.at_sampling_rate(rate), s, scene.num_splats) * (repeat + (i == 0))
        for rate in rates
        for s in settings
        for i, cam in enumerate(cams)
    )
    return sum(
        per_backend * (len(dict.fromkeys(simd)) if BACKENDS[b].capabilities.simd and simd else 1) for b in backends
    )


def ratios(rows: list[SpeedRow]) -> list[dict]:
    """Per scene, backend, SIMD path, rate and size: gaussian_blending / scalar (and its fast precision's,
    "gaussian_blending+fast / scalar", where measured) and supersample N x N /
    gaussian_blending (frame times); per mode, each vector SIMD path's blend-stage and frame speedup over the
    scalar path ("blend speedup avx2 over scalar": scalar's blend ms / avx2's)."""
    out = []
    index = {(r.scene, r.backend, r.simd_requested, r.rate, r.width, r.height, r.mode): r for r in rows}
    for (scene, backend, simd, rate, w, h, mode), r in index.items():
        where = {"scene": scene, "backend": backend, "simd": simd, "rate": rate, "width": w, "height": h}
        gb = index.get((scene, backend, simd, rate, w, h, "gaussian_blending"))
        fast = index.get((scene, backend, simd, rate, w, h, "gaussian_blending+fast"))
        if mode == "scalar" and gb:
            out.append({**where, "ratio": "gaussian_blending / scalar", "value": gb.median_ms / r.median_ms})
        if mode == "scalar" and fast:
            out.append({**where, "ratio": "gaussian_blending+fast / scalar", "value": fast.median_ms / r.median_ms})
        if mode.startswith("scalar:") and gb:
            out.append({**where, "ratio": f"{mode} / gaussian_blending", "value": r.median_ms / gb.median_ms})
    for (scene, backend, simd, rate, w, h, mode), r in index.items():
        base = index.get((scene, backend, "scalar", rate, w, h, mode))
        if simd in (None, "scalar") or base is None:
            continue
        where = {"scene": scene, "backend": backend, "simd": simd, "rate": rate, "width": w, "height": h, "mode": mode}
        out.append(
            {
                **where,
                "ratio": f"blend speedup {simd} over scalar",
                "value": base.stages_ms["blend_ms"] / max(r.stages_ms["blend_ms"], 1e-9),
            }
        )
        out.append({**where, "ratio": f"frame speedup {simd} over scalar", "value": base.median_ms / r.median_ms})
    return out
