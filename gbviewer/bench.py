"""Benchmarks: speed per mode, backend, sampling rate and SIMD path of the CPU backend; zoom fidelity (PSNR/SSIM)
against box-downsampled references. Everything measured in one run, reported as tables, JSON and plots."""

from __future__ import annotations

import json
import math
import os
import platform
import re
import statistics
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .camera import Camera, load_cameras_json, orbit_camera
from .errors import GBViewerError
from .figure import format_rate
from .io.files import atomic_write
from .render import BACKENDS, Mode, RenderSettings, get_renderer
from .scene import Scene

STAGES = ("preprocess_ms", "sort_ms", "blend_ms", "total_ms")
SIMD_NAMES = ("scalar", "avx2", "avx512")  # the CPU module's blend paths (GBVIEWER_SIMD)
EXP_RATE_N = 1 << 22  # exp evaluations per exp_rate call
MODE_COST = {Mode.ANALYTIC: 8.0, Mode.GAUSSIAN_BLENDING: 3.0}  # rough cost per sample against scalar, for the ETA


def _native():
    """The CPU module, with its SIMD API (simd_paths, simd, set_simd, exp_rate)."""
    from . import _native

    if not hasattr(_native, "set_simd"):
        raise GBViewerError(f"{_native.__file__} predates the SIMD paths (no set_simd/simd_paths/exp_rate): rebuild "
                            "it (pip install .)")
    return _native


def simd_paths() -> list[str]:
    """The SIMD paths of the CPU backend this CPU can run, best last (gbviewer._native.simd_paths())."""
    return [str(p) for p in _native().simd_paths()]


def current_simd() -> str:
    """The path the CPU backend renders with now: GBVIEWER_SIMD when the module loaded, else the best, until
    set_simd (gbviewer._native.simd())."""
    return str(_native().simd())


def set_simd(path: str) -> None:
    """Switch the CPU backend's path for later renders in this process (gbviewer._native.set_simd)."""
    _native().set_simd(path)


def parse_simd(text: str | None) -> list[str]:
    """`--simd`: comma-separated paths, `all` (every path this CPU runs) or `current` (the one in use); None, the
    default, is scalar and the path in use. Returned in simd_paths() order (scalar first, best last); a path this
    CPU cannot run is an error."""
    avail, cur = simd_paths(), current_simd()
    if text is None:
        wanted = ["scalar", cur]
    else:
        wanted = []
        for name in (t.strip().lower() for t in text.split(",")):
            if name == "all":
                wanted += avail
            elif name == "current":
                wanted.append(cur)
            elif name:
                wanted.append(name)
    if not wanted:
        raise GBViewerError("--simd: no SIMD path given")
    unknown = [w for w in wanted if w not in SIMD_NAMES]
    if unknown:
        raise GBViewerError(f"--simd: unknown SIMD path(s) {unknown}; expected some of {', '.join(SIMD_NAMES)}, "
                            "all or current")
    missing = [w for w in wanted if w not in avail]
    if missing:
        raise GBViewerError(f"--simd: this CPU cannot run {', '.join(missing)} (it runs {', '.join(avail)})")
    return sorted(dict.fromkeys(wanted), key=avail.index)


def exp_rates(paths: list[str] | None = None, n: int = EXP_RATE_N, tries: int = 3) -> dict[str, float]:
    """exp evaluations per second on one core for each SIMD path (gbviewer._native.exp_rate(path, n); the best of
    `tries`): the limit the blend's evaluation rate per core is measured against."""
    return {p: max(float(_native().exp_rate(p, n)) for _ in range(tries)) for p in (paths or simd_paths())}


def simd_info(measured: list[str]) -> dict:
    """The CPU backend's SIMD paths: those this CPU runs, the one in use, GBVIEWER_SIMD, the ones measured, and the
    exp throughput of each path (per second, one core)."""
    return {"paths": simd_paths(), "in_use": current_simd(), "env": os.environ.get("GBVIEWER_SIMD"),
            "measured": list(measured), "exp_per_s_per_core": exp_rates()}


def simd_summary(info: dict) -> str:
    """One line: 'SIMD scalar, avx2 (in use avx2; GBVIEWER_SIMD unset); exp per core: scalar 90M/s, avx2 400M/s'."""
    exp = ", ".join(f"{p} {v / 1e6:.0f}M/s" for p, v in info["exp_per_s_per_core"].items())
    env = info["env"] if info["env"] else "unset"
    return (f"SIMD paths {', '.join(info['paths'])} (in use {info['in_use']}; GBVIEWER_SIMD {env}; measuring "
            f"{', '.join(info['measured'])}); exp per core: {exp}")


def render_cost(cam: Camera, s: RenderSettings, splats: int) -> float:
    """A rough work estimate of one render (samples + splats, times a mode factor): the progress bar's unit."""
    return (cam.width * cam.height * s.supersample**2 + splats) * MODE_COST.get(s.mode, 1.0)


def box_downsample(img: np.ndarray, k: int) -> np.ndarray:
    """Mean over k x k blocks (the multi-scale Blender construction); crops a ragged edge."""
    h, w = img.shape[0] // k, img.shape[1] // k
    return img[: h * k, : w * k].reshape(h, k, w, k, *img.shape[2:]).mean(axis=(1, 3))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of images clipped to [0, 1]."""
    mse = float(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2))
    return math.inf if mse == 0 else -10.0 * math.log10(mse)


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM (scikit-image, Gaussian-weighted as in Wang et al.) of RGB images clipped to [0, 1]."""
    from skimage.metrics import structural_similarity

    a, b = np.clip(a, 0, 1).astype(np.float64), np.clip(b, 0, 1).astype(np.float64)
    if min(a.shape[:2]) < 11:  # the 11x11 Gaussian window (sigma 1.5) must fit
        return float("nan")
    return float(structural_similarity(a, b, channel_axis=2, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))


def bench_views(scene: Scene, views: int, width: int, height: int, cameras: Path | None = None,
                up: str = "-y", multiple: int = 1) -> list[Camera]:
    """Training cameras (resized to width x height) when given, else `views` orbit views around the robust bounds.
    The size is rounded down to a multiple of `multiple` (the largest zoom factor), so that every box-downsampled
    reference covers exactly the pixels of the low-rate render."""
    width, height = max(multiple, width // multiple * multiple), max(multiple, height // multiple * multiple)
    if cameras is not None:
        cams = load_cameras_json(cameras)
        step = max(1, len(cams) // views)
        return [c.with_size(width, height) for c in cams[::step][:views]]
    return [orbit_camera(scene, 360.0 * i / views, 20.0, width=width, height=height, up=up) for i in range(views)]


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


POP_THRESHOLD = 4.0 / 255.0


def flicker(frames: list[np.ndarray]) -> tuple[float, float]:
    """Popping along a slow camera path: frames I_0..I_{F-1} (clipped to [0, 1]) rendered at equal small steps.

    flicker = 255 x mean over t = 1..F-2, pixels and channels of |I_{t+1} - 2 I_t + I_{t-1}|, in 8-bit levels.
    Smooth motion at a constant step changes a pixel by about the same amount every frame, so its second
    difference is O(step^2); a sort-order swap (popping) is a step in one frame, which shows up at full size in the
    second difference of two consecutive t. pops = fraction of (pixel, t) whose largest channel |second difference|
    exceeds POP_THRESHOLD (4/255, a visible jump)."""
    if len(frames) < 3:
        return float("nan"), float("nan")
    f = np.clip(np.stack(frames).astype(np.float64), 0.0, 1.0)
    d2 = np.abs(f[2:] - 2.0 * f[1:-1] + f[:-2])
    return float(255.0 * d2.mean()), float((d2.max(axis=-1) > POP_THRESHOLD).mean())


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
    return sum(sum(2 * render_cost(c, s, scene.num_splats) + render_cost(c, wanted[Mode.SCALAR], scene.num_splats)
                   for c in cams) + flicker_frames * render_cost(cams[0], s, scene.num_splats)
               for s in wanted.values())


def measure_oit(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings], backend: str = "cpu",
                flicker_frames: int = 16, flicker_step: float = 0.1, up: str = "-y", progress=None) -> list[OitRow]:
    """scalar, wsr and duplex (those of `settings` at 1 sample per pixel, plus scalar as the reference) on the bench
    views, and the flicker of each along an orbit of `flicker_frames` frames, `flicker_step` degrees apart.
    progress(units) is called with render_cost units as renders finish (oit_cost() in all)."""
    wanted = oit_settings(settings)
    renderer = get_renderer(scene, backend)
    rows = []
    for mode, s in wanted.items():
        acc: dict[str, list] = {}
        last = None
        for cam in cams:
            ref = renderer.render(cam, RenderSettings(Mode.SCALAR)).rgb
            renderer.render(cam, s)  # warm-up (duplex: builds the cells once)
            f = renderer.render(cam, s)
            last = f.stats
            for k in STAGES + ("visible", "sort_length", "sort_bytes", "pairs", "cells", "cells_visible",
                               "cell_misses"):
                acc.setdefault(k, []).append(getattr(f.stats, k) or 0)
            acc.setdefault("psnr", []).append(psnr(f.rgb, ref))
            if progress:
                progress(2 * render_cost(cam, s, scene.num_splats) + render_cost(cam, wanted[Mode.SCALAR],
                                                                                 scene.num_splats))
        c0 = cams[0]
        frames = [renderer.render(orbit_camera(scene, 30.0 + i * flicker_step, 20.0, width=c0.width,
                                               height=c0.height, up=up), s).rgb for i in range(flicker_frames)]
        if progress:
            progress(flicker_frames * render_cost(c0, s, scene.num_splats))
        fl, pops = flicker(frames)
        mean = {k: float(np.mean(v)) for k, v in acc.items()}
        rows.append(OitRow(
            name, backend, s.spec, last.mode, c0.width, c0.height, round(mean["visible"]),
            round(mean["sort_length"]), mean["sort_bytes"] / 2**20, round(mean["pairs"]), round(mean["cells"]),
            round(mean["cells_visible"]), round(mean["cell_misses"]),
            {k: float(statistics.median(acc[k])) for k in STAGES}, mean["psnr"], fl, pops))
    return rows


def _console():
    """A rich console; into a file or pipe 200 columns wide, so that no number is cut short."""
    from rich.console import Console

    console = Console()
    return console if console.is_terminal else Console(width=max(console.width, 200))


def print_oit(rows: list[OitRow]) -> None:
    from rich.table import Table

    t = Table(title="Sorted vs order-independent modes (mean over views; flicker along a slow orbit)")
    for col in ("scene", "mode", "visible", "cells vis/all", "sort length", "sort MB", "list entries", "preprocess",
                "sort", "blend", "total ms", "PSNR vs scalar", "flicker", "pops %"):
        t.add_column(col, justify="left" if col in ("scene", "mode") else "right")
    for r in rows:
        cells = f"{r.cells_visible}/{r.cells}" if r.cells else "-"
        t.add_row(r.scene, r.label, str(r.visible), cells, str(r.sort_length), f"{r.sort_mb:.2f}", str(r.pairs),
                  f"{r.stages_ms['preprocess_ms']:.1f}", f"{r.stages_ms['sort_ms']:.1f}",
                  f"{r.stages_ms['blend_ms']:.1f}", f"{r.stages_ms['total_ms']:.1f}",
                  "inf" if math.isinf(r.psnr_vs_scalar) else f"{r.psnr_vs_scalar:.2f}", f"{r.flicker:.3f}",
                  f"{100 * r.pops:.3f}")
    _console().print(t)


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


def measure_speed(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings], backends: list[str],
                  rates: list[float], repeat: int, progress=None, simd: list[str] | None = None,
                  exp: dict[str, float] | None = None) -> list[SpeedRow]:
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
        cpu = backend == "cpu"
        before = active = current_simd() if cpu else None
        paths: list[str | None] = list(dict.fromkeys(simd)) if cpu and simd else [before]
        per_core = cores if cpu else 1
        try:
            for rate in rates:
                for s in settings:
                    acc = {p: {"totals": [], "stages": {k: [] for k in STAGES}, "evals": [], "last": None,
                               "diff": None} for p in paths}
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
                        ran = last.simd if cpu else None
                        rows.append(SpeedRow(
                            name, backend, s.spec, rate, c.width, c.height, statistics.median(totals), min(totals),
                            max(totals), med, last.visible, last.sort_length, float(np.mean(a["evals"])),
                            evals / max(sum(totals), 1e-9) / 1e3 / per_core, ran, path,
                            evals / max(sum(a["stages"]["blend_ms"]), 1e-9) / 1e3 / per_core,
                            exp[ran] / 1e6 if exp and ran in exp else None, a["diff"]))
        finally:
            if cpu and current_simd() != before:
                set_simd(before)
    return rows


@dataclass
class FidelityRow:
    scene: str
    mode: str
    rate: float
    kind: str  # "zoom-out" (vs x1 scalar, box-downsampled) or "zoom-in" (downsampled vs x1 of the same mode)
    psnr: float
    ssim: float
    simd: str | None = None  # the CPU backend's path that rendered it (Frame.stats.simd); None on other backends


def measure_fidelity(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings],
                     rates: list[float], backend: str = "cpu", progress=None) -> list[FidelityRow]:
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
            for rate in rates:
                k = round(1 / rate) if rate < 1 else round(rate)
                if rate == 1 or not math.isclose(k, 1 / rate if rate < 1 else rate, rel_tol=1e-6):
                    continue  # only integer factors have a box-downsampled reference
                c = cam.at_sampling_rate(rate)
                f = renderer.render(c, s)
                img = f.rgb
                if rate < 1:
                    ref, kind = box_downsample(ref_scalar, k), "zoom-out"
                else:
                    img, ref, kind = box_downsample(img, k), ref_same, "zoom-in"
                acc.setdefault((s.spec, rate, kind), []).append((psnr(img, ref), ssim(img, ref)))
                ran[s.spec, rate, kind] = f.stats.simd if backend == "cpu" else None
                if progress:
                    progress(render_cost(c, s, scene.num_splats))
    return [FidelityRow(name, spec, rate, kind, float(np.mean([p for p, _ in v])), float(np.mean([q for _, q in v])),
                        ran[spec, rate, kind]) for (spec, rate, kind), v in acc.items()]


def fidelity_cost(scene: Scene, cams: list[Camera], settings: list[RenderSettings], rates: list[float]) -> float:
    """The render_cost units measure_fidelity reports."""
    total = 0.0
    for cam in cams:
        total += render_cost(cam, RenderSettings(Mode.SCALAR), scene.num_splats)
        for s in settings:
            total += render_cost(cam, s, scene.num_splats)
            for rate in rates:
                k = round(1 / rate) if rate < 1 else round(rate)
                if rate != 1 and math.isclose(k, 1 / rate if rate < 1 else rate, rel_tol=1e-6):
                    total += render_cost(cam.at_sampling_rate(rate), s, scene.num_splats)
    return total


def speed_cost(scene: Scene, cams: list[Camera], settings: list[RenderSettings], backends: list[str],
               rates: list[float], repeat: int, simd: list[str] | None = None) -> float:
    """The render_cost units measure_speed reports."""
    per_backend = sum(render_cost(cam.at_sampling_rate(rate), s, scene.num_splats) * (repeat + (i == 0))
                      for rate in rates for s in settings for i, cam in enumerate(cams))
    return sum(per_backend * (len(dict.fromkeys(simd)) if b == "cpu" and simd else 1) for b in backends)


def ratios(rows: list[SpeedRow]) -> list[dict]:
    """Per scene, backend, SIMD path, rate and size: gaussian_blending / scalar and supersample N x N /
    gaussian_blending (frame times); per mode, each vector SIMD path's blend-stage and frame speedup over the
    scalar path ("blend speedup avx2 over scalar": scalar's blend ms / avx2's)."""
    out = []
    index = {(r.scene, r.backend, r.simd_requested, r.rate, r.width, r.height, r.mode): r for r in rows}
    for (scene, backend, simd, rate, w, h, mode), r in index.items():
        where = {"scene": scene, "backend": backend, "simd": simd, "rate": rate, "width": w, "height": h}
        gb = index.get((scene, backend, simd, rate, w, h, "gaussian_blending"))
        if mode == "scalar" and gb:
            out.append({**where, "ratio": "gaussian_blending / scalar", "value": gb.median_ms / r.median_ms})
        if mode.startswith("scalar:") and gb:
            out.append({**where, "ratio": f"{mode} / gaussian_blending", "value": r.median_ms / gb.median_ms})
    for (scene, backend, simd, rate, w, h, mode), r in index.items():
        base = index.get((scene, backend, "scalar", rate, w, h, mode))
        if simd in (None, "scalar") or base is None:
            continue
        where = {"scene": scene, "backend": backend, "simd": simd, "rate": rate, "width": w, "height": h, "mode": mode}
        out.append({**where, "ratio": f"blend speedup {simd} over scalar",
                    "value": base.stages_ms["blend_ms"] / max(r.stages_ms["blend_ms"], 1e-9)})
        out.append({**where, "ratio": f"frame speedup {simd} over scalar", "value": base.median_ms / r.median_ms})
    return out


def machine_description() -> dict:
    """CPU model, cores, Python, and the GL renderer when a GL backend is registered."""
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    desc = {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()}
    for name, cls in BACKENDS.items():
        info = getattr(cls, "describe", None)
        if info is not None:
            desc[f"{name}_backend"] = info()
    return desc


def write_json(path: Path, speed: list[SpeedRow], fidelity: list[FidelityRow], force: bool = False,
               oit: list[OitRow] | None = None, simd: dict | None = None) -> Path:
    """Every number: machine, simd (simd_info()), speed, fidelity, ratios, order_independent."""
    doc = {"machine": machine_description(), "simd": simd, "speed": [asdict(r) for r in speed],
           "fidelity": [asdict(r) for r in fidelity], "ratios": ratios(speed)}
    if oit:
        doc["order_independent"] = [asdict(r) for r in oit]
    return atomic_write(path, lambda p: p.write_text(json.dumps(doc, indent=2, allow_nan=True)), force)


def write_plots(out_dir: Path, speed: list[SpeedRow], fidelity: list[FidelityRow], force: bool = False) -> list[Path]:
    """PSNR vs sampling rate per mode, and time per mode (one figure per scene), as PNG; existing plots are only
    replaced with `force`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for scene in sorted({r.scene for r in speed} | {r.scene for r in fidelity}):
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
        fid = [r for r in fidelity if r.scene == scene]
        for mode in dict.fromkeys(r.mode for r in fid):
            pts = sorted((r.rate, r.psnr) for r in fid if r.mode == mode)
            ax1.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=mode)
        ax1.set_xscale("log", base=2)
        ax1.set_xlabel("sampling rate")
        ax1.set_ylabel("PSNR (dB)")
        ax1.set_title(f"{scene}: zoom fidelity")
        ax1.legend(fontsize=8)
        sp = [r for r in speed if r.scene == scene and r.rate == 1.0]
        labels = [f"{r.mode}\n{r.backend}" + (f" {r.simd_requested}" if r.simd_requested else "") for r in sp]
        bottoms = np.zeros(len(sp))
        for stage in ("preprocess_ms", "sort_ms", "blend_ms"):
            vals = np.array([r.stages_ms[stage] for r in sp])
            ax2.bar(labels, vals, bottom=bottoms, label=stage.removesuffix("_ms"))
            bottoms += vals
        ax2.set_ylabel("ms per frame (x1)")
        ax2.set_title(f"{scene}: time per mode")
        ax2.legend(fontsize=8)
        ax2.tick_params(axis="x", labelsize=7)
        fig.tight_layout()
        path = out_dir / (re.sub(r"[^A-Za-z0-9._-]+", "_", Path(scene).stem) + ".png")
        try:
            atomic_write(path, lambda p: fig.savefig(p, dpi=110, format="png"), force)
        finally:
            plt.close(fig)
        written.append(path)
    return written


def simd_table(rows: list[SpeedRow]) -> tuple[list[str], list[list[str]]]:
    """The CPU backend's SIMD paths side by side (rows of the same scene, rate, size and mode measured on more than
    one path): blend ms per path, each vector path's blend and frame speedup over scalar, blend evaluations per
    second per core against that path's exp rate, and the largest difference from the scalar path's image."""
    groups: dict[tuple, dict[str, SpeedRow]] = {}
    for r in rows:
        if r.backend == "cpu" and r.simd_requested:
            groups.setdefault((r.scene, r.rate, r.width, r.height, r.mode), {})[r.simd_requested] = r
    groups = {k: v for k, v in groups.items() if len(v) > 1}
    paths = list(dict.fromkeys(p for g in groups.values() for p in g))
    order = {p: i for i, p in enumerate(SIMD_NAMES)}
    paths.sort(key=lambda p: order.get(p, len(order)))
    vector = [p for p in paths if p != "scalar"]
    header = ["scene", "mode", "rate", "size"] + [f"{p} blend ms" for p in paths]
    for p in vector:
        header += [f"{p} blend speedup", f"{p} frame speedup"]
    header += [f"{p} blend Mevals/s/core (exp)" for p in paths] + [f"{p} max abs diff" for p in vector]
    out = []
    for (scene, rate, w, h, mode), g in groups.items():
        row = [scene, mode, format_rate(rate), f"{w}x{h}"]
        for p in paths:
            r = g.get(p)
            row.append("" if r is None else f"{r.stages_ms['blend_ms']:.1f}"
                       + (f" (ran {r.simd})" if r.simd and r.simd != p else ""))
        base = g.get("scalar")
        for p in vector:
            r = g.get(p)
            if r is None or base is None:
                row += ["", ""]
            else:
                row += [f"{base.stages_ms['blend_ms'] / max(r.stages_ms['blend_ms'], 1e-9):.2f}",
                        f"{base.median_ms / r.median_ms:.2f}"]
        for p in paths:
            r = g.get(p)
            exp = f" ({r.exp_mevals_per_s_per_core:.0f})" if r is not None and r.exp_mevals_per_s_per_core else ""
            row.append("" if r is None else f"{r.blend_mevals_per_s_per_core:.0f}{exp}")
        for p in vector:
            r = g.get(p)
            row.append("" if r is None or r.simd_max_abs_diff is None else f"{r.simd_max_abs_diff:.2g}")
        out.append(row)
    return header, out


def print_tables(speed: list[SpeedRow], fidelity: list[FidelityRow], simd: dict | None = None) -> None:
    """Rich tables on the terminal: speed, SIMD paths, ratios, fidelity; `simd` (simd_info()) heads them."""
    from rich.table import Table

    console = _console()
    if simd:
        console.print(simd_summary(simd), highlight=False)
    t = Table(title="Speed (median over repeats and views; Mevals/s/core: splat-pixel evaluations per second per "
                    "core over the frame / the blend stage, exp: that SIMD path's exp evaluations per second on a "
                    "core)")
    for col in ("scene", "backend", "simd", "mode", "rate", "size", "total ms", "min-max", "preprocess", "sort",
                "blend", "evals/px", "Mevals/s/core", "blend Mevals/s/core", "exp M/s/core"):
        t.add_column(col, justify="right" if col not in ("scene", "backend", "simd", "mode") else "left")
    for r in speed:
        t.add_row(r.scene, r.backend, r.simd or "-", r.mode, format_rate(r.rate), f"{r.width}x{r.height}",
                  f"{r.median_ms:.1f}", f"{r.min_ms:.1f}-{r.max_ms:.1f}", f"{r.stages_ms['preprocess_ms']:.1f}",
                  f"{r.stages_ms['sort_ms']:.1f}", f"{r.stages_ms['blend_ms']:.1f}", f"{r.evals_per_pixel:.1f}",
                  f"{r.mevals_per_s_per_core:.1f}", f"{r.blend_mevals_per_s_per_core:.1f}",
                  "-" if r.exp_mevals_per_s_per_core is None else f"{r.exp_mevals_per_s_per_core:.0f}")
    console.print(t)
    header, rows = simd_table(speed)
    if rows:
        st = Table(title="SIMD paths of the CPU backend (same run, taking turns render by render; speedup: scalar's "
                         "ms / the path's; exp: the path's exp evaluations per second on a core; max abs diff: largest "
                         "rgb difference from the scalar path's image)")
        for col in header:
            st.add_column(col, justify="left" if col in ("scene", "mode") else "right")
        for row in rows:
            st.add_row(*row)
        console.print(st)
    rt = Table(title="Ratios of frame times (same run; the SIMD speedups are in the table above)")
    for col in ("scene", "backend", "simd", "rate", "size", "ratio", "value"):
        rt.add_column(col)
    for r in ratios(speed):
        if "mode" not in r:
            rt.add_row(r["scene"], r["backend"], r["simd"] or "-", format_rate(r["rate"]),
                       f"{r['width']}x{r['height']}", r["ratio"], f"{r['value']:.2f}")
    console.print(rt)
    if fidelity:
        ft = Table(title="Zoom fidelity (mean over views)")
        for col in ("scene", "kind", "rate", "mode", "simd", "PSNR dB", "SSIM"):
            ft.add_column(col)
        for r in sorted(fidelity, key=lambda r: (r.scene, r.kind, -r.rate if r.kind == "zoom-out" else r.rate)):
            ft.add_row(r.scene, r.kind, format_rate(r.rate), r.mode, r.simd or "-", f"{r.psnr:.2f}", f"{r.ssim:.4f}")
        console.print(ft)
