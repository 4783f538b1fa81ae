"""The benchmark's report: rich tables on the terminal, every number as JSON with the machine description, plots."""

from __future__ import annotations

import math
import os
import platform
import re
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..core.extras import require
from ..core.files import atomic_write
from ..core.validate import dumps_json
from ..io.datasets.backdrop import choose_background
from ..model.camera import format_rate
from ..outputs.console import wide_console
from ..render import BACKENDS
from .fidelity import FidelityRow
from .oit import OitRow
from .simd import SIMD_NAMES, simd_summary
from .speed import SpeedRow, ratios
from .stability import FlickerRow

BENCH_BACKGROUND = choose_background(None, None)  # the one rule without photos: every bench render is on black


def print_oit(rows: list[OitRow]) -> None:
    from rich.table import Table

    t = Table(
        title="Sorted vs order-independent modes (mean over views; popping along a slow orbit: the frames' "
        "second difference, metrics.flicker, not the shimmer against a reference of `gbviewer flicker`)"
    )
    for col in (
        "scene",
        "mode",
        "visible",
        "cells vis/all",
        "sort length",
        "sort MB",
        "list entries",
        "preprocess",
        "sort",
        "blend",
        "total ms",
        "PSNR vs scalar",
        "popping (2nd diff)",
        "pops %",
    ):
        t.add_column(col, justify="left" if col in ("scene", "mode") else "right")
    for r in rows:
        cells = f"{r.cells_visible}/{r.cells}" if r.cells else "-"
        t.add_row(
            r.scene,
            r.label,
            str(r.visible),
            cells,
            str(r.sort_length),
            f"{r.sort_mb:.2f}",
            str(r.pairs),
            f"{r.stages_ms['preprocess_ms']:.1f}",
            f"{r.stages_ms['sort_ms']:.1f}",
            f"{r.stages_ms['blend_ms']:.1f}",
            f"{r.stages_ms['total_ms']:.1f}",
            "inf" if math.isinf(r.psnr_vs_scalar) else f"{r.psnr_vs_scalar:.2f}",
            f"{r.flicker:.3f}",
            f"{100 * r.pops:.3f}",
        )
    wide_console().print(t)


def print_flicker(rows: list[FlickerRow]) -> None:
    """Flicker and change per mode (gbviewer.outputs.flicker), and each scene's floor."""
    from rich.table import Table

    t = Table(
        title="Flicker along a zoom x1 -> x1/4 (8-bit levels: frame-to-frame change minus the reference's; "
        "floor: the reference at half its samples per axis against it)"
    )
    for col in ("scene", "mode", "size", "pairs", "flicker", "change", "x floor", "floor", "reference"):
        t.add_column(col, justify="left" if col in ("scene", "mode", "reference") else "right")
    for r in rows:
        t.add_row(
            r.scene,
            r.label,
            f"{r.width}x{r.height}",
            str(r.pairs),
            f"{r.flicker:.3f}",
            f"{r.change:.3f}",
            f"{r.flicker / r.floor:.2f}" if r.floor else "-",
            "-" if r.floor is None else f"{r.floor:.3f}",
            r.reference,
        )
    wide_console().print(t)


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


def write_json(
    path: Path,
    speed: list[SpeedRow],
    fidelity: list[FidelityRow],
    force: bool = False,
    oit: list[OitRow] | None = None,
    simd: dict | None = None,
    flicker: list[FlickerRow] | None = None,
) -> Path:
    """Every number: machine, simd (simd_info()), speed, fidelity, ratios, flicker, order_independent."""
    doc = {
        "machine": machine_description(),
        "simd": simd,
        "background": BENCH_BACKGROUND.to_json(),
        "speed": [asdict(r) for r in speed],
        "fidelity": [asdict(r) for r in fidelity],
        "ratios": ratios(speed),
    }
    if flicker:
        doc["flicker"] = [asdict(r) for r in flicker]
    if oit:
        doc["order_independent"] = [asdict(r) for r in oit]
    return atomic_write(path, lambda p: p.write_text(dumps_json(doc, indent=2)), force)


def plot_path(out_dir: Path, scene: str) -> Path:
    """Where `write_plots` puts the plots of the scene named `scene`."""
    return out_dir / (re.sub(r"[^A-Za-z0-9._-]+", "_", Path(scene).stem) + ".png")


MARKERS = "os^Dv"  # a mode past matplotlib's 10 cycle colours gets another marker and dash (line_style)
DASHES = ("-", "--", ":", "-.")


def line_style(i: int) -> dict:
    """The plot line of the i-th mode: matplotlib's 10 cycle colours, then the same colours with another marker and
    dash, so that every mode of a plot stays distinguishable in its legend however many modes it has."""
    k = i // 10
    return {"color": f"C{i % 10}", "marker": MARKERS[k % len(MARKERS)], "linestyle": DASHES[k % len(DASHES)]}


def write_plots(out_dir: Path, speed: list[SpeedRow], fidelity: list[FidelityRow], force: bool = False) -> list[Path]:
    """PSNR vs sampling rate per mode, time per mode, and quality against cost (zoom-out PSNR against frame time,
    one line per mode through its rates): one figure per scene, as PNG; existing plots are only replaced with
    `force`."""
    plt = pyplot()
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for scene in sorted({r.scene for r in speed} | {r.scene for r in fidelity}):
        fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(18, 4.5))
        fid = [r for r in fidelity if r.scene == scene]
        styles = {mode: line_style(i) for i, mode in enumerate(dict.fromkeys(r.mode for r in fid))}
        for mode, style in styles.items():
            pts = sorted((r.rate, r.psnr) for r in fid if r.mode == mode)
            ax1.plot([p[0] for p in pts], [p[1] for p in pts], label=mode, **style)
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
        quality_cost(ax3, scene, [r for r in speed if r.scene == scene], fid, styles)
        fig.tight_layout()
        path = plot_path(out_dir, scene)
        save_figure(fig, path, force)
        written.append(path)
    return written


def quality_cost(ax, scene: str, speed: list[SpeedRow], fidelity: list[FidelityRow], styles: dict[str, dict]) -> None:
    """Zoom-out PSNR against the frame time (the fastest path measured) of each mode, a line through its rates
    labelled x1/k, drawn in its `styles` entry (`line_style`)."""
    for mode in dict.fromkeys(r.mode for r in fidelity if r.kind == "zoom-out"):
        pts = []
        for f in sorted((r for r in fidelity if r.mode == mode and r.kind == "zoom-out"), key=lambda r: r.rate):
            ms = [r.median_ms for r in speed if r.mode == mode and r.rate == f.rate]
            if ms:
                pts.append((min(ms), f.psnr, f.rate))
        if pts:
            (line,) = ax.plot([p[0] for p in pts], [p[1] for p in pts], label=mode, **styles[mode])
            for ms, db, rate in pts:
                ax.annotate(
                    f"x1/{round(1 / rate)}",
                    (ms, db),
                    fontsize=6,
                    color=line.get_color(),
                    xytext=(3, 3),
                    textcoords="offset points",
                )
    ax.set_xscale("log")
    ax.set_xlabel("ms per frame (median, fastest path)")
    ax.set_ylabel("PSNR vs reference (dB)")
    ax.set_title(f"{scene}: quality against cost (zoom-out)")
    ax.legend(fontsize=8)


def pyplot():
    """matplotlib.pyplot on its Agg backend (the [eval] extra)."""
    require("eval", "matplotlib", "plots").use("Agg")
    return require("eval", "matplotlib.pyplot", "plots")


def save_figure(fig, path: Path, force: bool) -> None:
    """A matplotlib figure as a PNG, written atomically (refusing to overwrite unless `force`), then closed."""
    try:
        atomic_write(path, lambda p: fig.savefig(p, dpi=110, format="png"), force)
    finally:
        pyplot().close(fig)


def simd_table(rows: list[SpeedRow]) -> tuple[list[str], list[list[str]]]:
    """The CPU backend's SIMD paths side by side (rows of the same scene, rate, size and mode measured on more than
    one path): blend ms per path, each vector path's blend and frame speedup over scalar, blend evaluations per
    second per core against that path's exp rate, and the largest difference from the scalar path's image."""
    groups: dict[tuple, dict[str, SpeedRow]] = {}
    for r in rows:
        if r.simd_requested:  # set on backends with SIMD paths only
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
            row.append(
                ""
                if r is None
                else f"{r.stages_ms['blend_ms']:.1f}" + (f" (ran {r.simd})" if r.simd and r.simd != p else "")
            )
        base = g.get("scalar")
        for p in vector:
            r = g.get(p)
            if r is None or base is None:
                row += ["", ""]
            else:
                row += [
                    f"{base.stages_ms['blend_ms'] / max(r.stages_ms['blend_ms'], 1e-9):.2f}",
                    f"{base.median_ms / r.median_ms:.2f}",
                ]
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

    out = wide_console()
    if simd:
        out.print(simd_summary(simd), highlight=False)
    out.print(f"background {BENCH_BACKGROUND.describe()}", highlight=False)
    t = Table(
        title="Speed (median over repeats and views; Mevals/s/core: splat-pixel evaluations per second per "
        "core over the frame / the blend stage, exp: that SIMD path's exp evaluations per second on a "
        "core)"
    )
    for col in (
        "scene",
        "backend",
        "simd",
        "mode",
        "rate",
        "size",
        "total ms",
        "min-max",
        "preprocess",
        "sort",
        "blend",
        "evals/px",
        "Mevals/s/core",
        "blend Mevals/s/core",
        "exp M/s/core",
    ):
        t.add_column(col, justify="right" if col not in ("scene", "backend", "simd", "mode") else "left")
    for r in speed:
        t.add_row(
            r.scene,
            r.backend,
            r.simd or "-",
            r.mode,
            format_rate(r.rate),
            f"{r.width}x{r.height}",
            f"{r.median_ms:.1f}",
            f"{r.min_ms:.1f}-{r.max_ms:.1f}",
            f"{r.stages_ms['preprocess_ms']:.1f}",
            f"{r.stages_ms['sort_ms']:.1f}",
            f"{r.stages_ms['blend_ms']:.1f}",
            f"{r.evals_per_pixel:.1f}",
            f"{r.mevals_per_s_per_core:.1f}",
            f"{r.blend_mevals_per_s_per_core:.1f}",
            "-" if r.exp_mevals_per_s_per_core is None else f"{r.exp_mevals_per_s_per_core:.0f}",
        )
    out.print(t)
    header, rows = simd_table(speed)
    if rows:
        st = Table(
            title="SIMD paths of the CPU backend (same run, taking turns render by render; speedup: scalar's "
            "ms / the path's; exp: the path's exp evaluations per second on a core; max abs diff: largest "
            "rgb difference from the scalar path's image)"
        )
        for col in header:
            st.add_column(col, justify="left" if col in ("scene", "mode") else "right")
        for row in rows:
            st.add_row(*row)
        out.print(st)
    rt = Table(title="Ratios of frame times (same run; the SIMD speedups are in the table above)")
    for col in ("scene", "backend", "simd", "rate", "size", "ratio", "value"):
        rt.add_column(col)
    for r in ratios(speed):
        if "mode" not in r:
            rt.add_row(
                r["scene"],
                r["backend"],
                r["simd"] or "-",
                format_rate(r["rate"]),
                f"{r['width']}x{r['height']}",
                r["ratio"],
                f"{r['value']:.2f}",
            )
    out.print(rt)
    if fidelity:
        ft = Table(title="Zoom fidelity (mean over views)")
        for col in ("scene", "kind", "rate", "mode", "simd", "PSNR dB", "SSIM"):
            ft.add_column(col)
        for r in sorted(fidelity, key=lambda r: (r.scene, r.kind, -r.rate if r.kind == "zoom-out" else r.rate)):
            ft.add_row(r.scene, r.kind, format_rate(r.rate), r.mode, r.simd or "-", f"{r.psnr:.2f}", f"{r.ssim:.4f}")
        out.print(ft)
