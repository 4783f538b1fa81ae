"""The evaluation's report: the paper's table per scene (rows modes; PSNR and SSIM per rate and their average) and
the mean over scenes on the terminal, every view's numbers as JSON, plots."""

from __future__ import annotations

from pathlib import Path

from ..bench.report import line_style, machine_description, plot_path, pyplot, save_figure
from ..core.files import atomic_write
from ..core.validate import dumps_json
from ..model.camera import format_rate
from ..outputs.console import wide_console
from .run import EvalResult, mean

Table = dict[tuple[str, float], dict[str, float | None]]  # (mode, rate) -> psnr, ssim, render_ms


def mean_table(tables: list[Table]) -> Table:
    """The mean over scenes of their tables."""
    return {key: {m: mean([t[key][m] for t in tables]) for m in ("psnr", "ssim", "render_ms")} for key in tables[0]}


def averages(table: Table, modes: list[str], rates: list[float]) -> dict[str, dict[str, float | None]]:
    """mode -> PSNR and SSIM averaged over the rates (the paper's Avg. column)."""
    return {m: {k: mean([table[m, r][k] for r in rates]) for k in ("psnr", "ssim")} for m in modes}


def _fmt(x: float | None, digits: int) -> str:
    """A table cell: the number, or n/a."""
    return "n/a" if x is None else f"{x:.{digits}f}"


def _print_table(title: str, table: Table, result: EvalResult) -> None:
    """The paper's layout: a row per mode; PSNR per rate and average, SSIM likewise, render ms at the top rate."""
    from rich.table import Table as RichTable

    rates, modes = result.rates, result.modes
    t = RichTable(title=title)
    t.add_column("mode")
    for metric in ("PSNR", "SSIM"):
        for r in rates:
            t.add_column(f"{metric} {format_rate(r)}", justify="right")
        t.add_column(f"{metric} avg", justify="right")
    t.add_column(f"ms {format_rate(max(rates))}", justify="right")
    avg = averages(table, modes, rates)
    for m in modes:
        t.add_row(
            m,
            *[_fmt(table[m, r]["psnr"], 2) for r in rates],
            _fmt(avg[m]["psnr"], 2),
            *[_fmt(table[m, r]["ssim"], 4) for r in rates],
            _fmt(avg[m]["ssim"], 4),
            _fmt(table[m, max(rates)]["render_ms"], 1),
        )
    wide_console().print(t)


def print_tables(result: EvalResult) -> None:
    """One table per scene, then the mean over scenes where there are several."""
    for s in result.scenes:
        backends = ", ".join(sorted({v.backend for v in s.results}))
        _print_table(
            f"{s.scene.name} against {s.dataset.name} ({s.format}, {result.split}: {len(s.views)} views, "
            f"{backends}; ms: mean render time; background {s.background.describe()})",
            s.table(),
            result,
        )
    if len(result.scenes) > 1:
        _print_table(f"Mean over {len(result.scenes)} scenes", mean_table([s.table() for s in result.scenes]), result)
    wide_console().print(
        f"{sum(len(s.views) for s in result.scenes)} views in {result.elapsed_s:.1f} s on {result.runner}",
        highlight=False,
    )


def _rows(table: Table, result: EvalResult) -> dict:
    """A table and its averages as JSON rows."""
    return {
        "table": [{"mode": m, "rate": r, "rate_label": format_rate(r), **v} for (m, r), v in table.items()],
        "average": [{"mode": m, **v} for m, v in averages(table, result.modes, result.rates).items()],
    }


def to_json(result: EvalResult) -> dict:
    """Every view's numbers, each scene's table and averages, their mean over scenes, and how it ran. Missing
    numbers (SSIM of an image under 11 pixels, identical images' PSNR) are null."""
    scenes = [
        {
            "scene": str(s.scene),
            "dataset": str(s.dataset),
            "format": s.format,
            "background": s.background.to_json(),
            **_rows(s.table(), result),
            "views": [
                {
                    "name": v.name,
                    "image": str(v.image),
                    "width": v.camera.width,
                    "height": v.camera.height,
                    "backend": r.backend,
                    "results": r.results,
                }
                for v, r in zip(s.views, s.results)
            ],
        }
        for s in result.scenes
    ]
    return {
        "modes": result.modes,
        "rates": result.rates,
        "split": result.split,
        "background": None if result.background is None else list(result.background),
        "runner": result.runner,
        "elapsed_s": result.elapsed_s,
        "machine": machine_description(),
        "scenes": scenes,
        "mean": _rows(mean_table([s.table() for s in result.scenes]), result),
    }


def write_json(path: Path, result: EvalResult, force: bool = False) -> Path:
    """`to_json` written atomically (an existing file only with `force`)."""
    doc = to_json(result)
    return atomic_write(path, lambda p: p.write_text(dumps_json(doc, indent=1)), force)


def _labels(pairs: list[tuple[Path, Path]]) -> list[str]:
    """Each scene's name, with its dataset's where one scene is evaluated against several."""
    names = [Path(scene).stem for scene, _ in pairs]
    return [n if names.count(n) == 1 else f"{n} vs {Path(data).resolve().name}" for n, (_, data) in zip(names, pairs)]


def plot_paths(out_dir: Path, pairs: list[tuple[Path, Path]]) -> list[Path]:
    """Where `write_plots` puts the plots of these (scene, dataset) pairs: one per scene, and mean.png for several."""
    return [plot_path(out_dir, n) for n in _labels(pairs) + (["mean"] if len(pairs) > 1 else [])]


def write_plots(out_dir: Path, result: EvalResult, force: bool = False) -> list[Path]:
    """PSNR and SSIM against the sampling rate, one line per mode, per scene (and for the mean)."""
    plt = pyplot()
    pairs = [(s.scene, s.dataset) for s in result.scenes]
    tables = [s.table() for s in result.scenes]
    titles = _labels(pairs)
    if len(tables) > 1:
        tables, titles = tables + [mean_table(tables)], titles + [f"mean over {len(tables)} scenes"]
    written = []
    for table, title, path in zip(tables, titles, plot_paths(out_dir, pairs)):
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        for ax, metric in zip(axes, ("psnr", "ssim")):
            for i, m in enumerate(result.modes):
                pts = sorted((r, table[m, r][metric]) for r in result.rates if table[m, r][metric] is not None)
                ax.plot([p[0] for p in pts], [p[1] for p in pts], label=m, **line_style(i))
            ax.set_xscale("log", base=2)
            ax.set_xticks(sorted(result.rates), [format_rate(r) for r in sorted(result.rates)])
            ax.set_xlabel("sampling rate (x1: the photos)")
            ax.set_ylabel("PSNR (dB)" if metric == "psnr" else "SSIM")
            ax.set_title(f"{title}: {metric.upper()} against the photos")
            ax.legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, path, force)
        written.append(path)
    return written
