"""Benchmarks: speed per mode, backend and sampling rate; zoom fidelity (PSNR/SSIM) against box-downsampled
references. Everything measured in one run, reported as tables, JSON and plots."""

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
from .figure import format_rate
from .io.files import atomic_write
from .render import BACKENDS, Mode, RenderSettings, get_renderer
from .scene import Scene

STAGES = ("preprocess_ms", "sort_ms", "blend_ms", "total_ms")


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


def measure_oit(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings], backend: str = "cpu",
                flicker_frames: int = 16, flicker_step: float = 0.1, up: str = "-y", progress=None) -> list[OitRow]:
    """scalar, wsr and duplex (those of `settings` at 1 sample per pixel, plus scalar as the reference) on the bench
    views, and the flicker of each along an orbit of `flicker_frames` frames, `flicker_step` degrees apart."""
    wanted = {Mode.SCALAR: RenderSettings(Mode.SCALAR)}
    for s in settings:
        if s.mode in (Mode.WSR, Mode.DUPLEX) and s.supersample == 1:
            wanted.setdefault(s.mode, s)
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
                acc.setdefault(k, []).append(f.stats.get(k, 0))
            acc.setdefault("psnr", []).append(psnr(f.rgb, ref))
            if progress:
                progress()
        c0 = cams[0]
        frames = [renderer.render(orbit_camera(scene, 30.0 + i * flicker_step, 20.0, width=c0.width,
                                               height=c0.height, up=up), s).rgb for i in range(flicker_frames)]
        fl, pops = flicker(frames)
        mean = {k: float(np.mean(v)) for k, v in acc.items()}
        rows.append(OitRow(
            name, backend, s.spec, last["mode"], c0.width, c0.height, round(mean["visible"]),
            round(mean["sort_length"]), mean["sort_bytes"] / 2**20, round(mean["pairs"]), round(mean["cells"]),
            round(mean["cells_visible"]), round(mean["cell_misses"]),
            {k: float(statistics.median(acc[k])) for k in STAGES}, mean["psnr"], fl, pops))
    return rows


def print_oit(rows: list[OitRow]) -> None:
    from rich.console import Console
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
    Console().print(t)


@dataclass
class SpeedRow:
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


def measure_speed(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings], backends: list[str],
                  rates: list[float], repeat: int, progress=None) -> list[SpeedRow]:
    """Median over `repeat` renders (after one warm-up) of every view, per backend, mode and rate."""
    rows = []
    cores = os.cpu_count() or 1
    for backend in backends:
        renderer = get_renderer(scene, backend)
        for rate in rates:
            for s in settings:
                totals, stages, last = [], {k: [] for k in STAGES}, None
                for cam in cams:
                    c = cam.at_sampling_rate(rate)
                    renderer.render(c, s)  # warm-up: first-touch allocations, caches
                    for _ in range(repeat):
                        last = renderer.render(c, s).stats
                        totals.append(last["total_ms"])
                        for k in STAGES:
                            stages[k].append(last[k])
                    if progress:
                        progress()
                med = {k: statistics.median(v) for k, v in stages.items()}
                per_core = cores if backend == "cpu" else 1
                rows.append(SpeedRow(
                    name, backend, s.spec, rate, c.width, c.height, statistics.median(totals), min(totals),
                    max(totals), med, last["visible"], last["sort_length"], last["evals_per_pixel"],
                    last["evals_per_pixel"] * c.width * c.height / max(med["total_ms"], 1e-9) / 1e3 / per_core))
    return rows


@dataclass
class FidelityRow:
    scene: str
    mode: str
    rate: float
    kind: str  # "zoom-out" (vs x1 scalar, box-downsampled) or "zoom-in" (downsampled vs x1 of the same mode)
    psnr: float
    ssim: float


def measure_fidelity(scene: Scene, name: str, cams: list[Camera], settings: list[RenderSettings],
                     rates: list[float], backend: str = "cpu", progress=None) -> list[FidelityRow]:
    """Zoom-out: each mode at rate 1/k against the x1 scalar render box-downsampled by k.
    Zoom-in: each mode at rate k box-downsampled by k against the x1 render of the same mode."""
    renderer = get_renderer(scene, backend)
    acc: dict[tuple[str, float, str], list[tuple[float, float]]] = {}
    for cam in cams:
        ref_scalar = renderer.render(cam, RenderSettings(Mode.SCALAR)).rgb
        for s in settings:
            ref_same = renderer.render(cam, s).rgb
            for rate in rates:
                k = round(1 / rate) if rate < 1 else round(rate)
                if rate == 1 or not math.isclose(k, 1 / rate if rate < 1 else rate, rel_tol=1e-6):
                    continue  # only integer factors have a box-downsampled reference
                img = renderer.render(cam.at_sampling_rate(rate), s).rgb
                if rate < 1:
                    ref, kind = box_downsample(ref_scalar, k), "zoom-out"
                else:
                    img, ref, kind = box_downsample(img, k), ref_same, "zoom-in"
                acc.setdefault((s.spec, rate, kind), []).append((psnr(img, ref), ssim(img, ref)))
                if progress:
                    progress()
    return [FidelityRow(name, spec, rate, kind, float(np.mean([p for p, _ in v])), float(np.mean([q for _, q in v])))
            for (spec, rate, kind), v in acc.items()]


def ratios(rows: list[SpeedRow]) -> list[dict]:
    """gaussian_blending / scalar and supersample N x N / gaussian_blending, per scene, backend and rate."""
    out = []
    index = {(r.scene, r.backend, r.rate, r.mode): r.median_ms for r in rows}
    for (scene, backend, rate, mode), ms in index.items():
        gb = index.get((scene, backend, rate, "gaussian_blending"))
        if mode == "scalar" and gb:
            out.append({"scene": scene, "backend": backend, "rate": rate, "ratio": "gaussian_blending / scalar",
                        "value": gb / ms})
        if mode.startswith("scalar:") and gb:
            out.append({"scene": scene, "backend": backend, "rate": rate, "ratio": f"{mode} / gaussian_blending",
                        "value": ms / gb})
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
               oit: list[OitRow] | None = None) -> Path:
    doc = {"machine": machine_description(), "speed": [asdict(r) for r in speed],
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
        labels = [f"{r.mode}\n{r.backend}" for r in sp]
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


def print_tables(speed: list[SpeedRow], fidelity: list[FidelityRow]) -> None:
    """Rich tables on the terminal: speed, ratios, fidelity."""
    from rich.console import Console
    from rich.table import Table

    console = Console()
    t = Table(title="Speed (median over repeats and views)")
    for col in ("scene", "backend", "mode", "rate", "size", "total ms", "min-max", "preprocess", "sort", "blend",
                "evals/px", "Mevals/s/core"):
        t.add_column(col, justify="right" if col not in ("scene", "backend", "mode") else "left")
    for r in speed:
        t.add_row(r.scene, r.backend, r.mode, format_rate(r.rate), f"{r.width}x{r.height}", f"{r.median_ms:.1f}",
                  f"{r.min_ms:.1f}-{r.max_ms:.1f}", f"{r.stages_ms['preprocess_ms']:.1f}",
                  f"{r.stages_ms['sort_ms']:.1f}", f"{r.stages_ms['blend_ms']:.1f}", f"{r.evals_per_pixel:.1f}",
                  f"{r.mevals_per_s_per_core:.1f}")
    console.print(t)
    rt = Table(title="Ratios (same run)")
    for col in ("scene", "backend", "rate", "ratio", "value"):
        rt.add_column(col)
    for r in ratios(speed):
        rt.add_row(r["scene"], r["backend"], format_rate(r["rate"]), r["ratio"], f"{r['value']:.2f}")
    console.print(rt)
    if fidelity:
        ft = Table(title="Zoom fidelity (mean over views)")
        for col in ("scene", "kind", "rate", "mode", "PSNR dB", "SSIM"):
            ft.add_column(col)
        for r in sorted(fidelity, key=lambda r: (r.scene, r.kind, -r.rate if r.kind == "zoom-out" else r.rate)):
            ft.add_row(r.scene, r.kind, format_rate(r.rate), r.mode, f"{r.psnr:.2f}", f"{r.ssim:.4f}")
        console.print(ft)
