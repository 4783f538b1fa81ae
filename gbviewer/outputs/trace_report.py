"""Pixel traces for people and files: `gbviewer trace`'s rich tables (one per mode: the top contributors, the
rejections counted by reason, the colour and transmittance) and its JSON file; the viewer's CSV of them (one row
per step)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from ..core.files import atomic_write
from ..core.validate import dumps_json
from ..render import PixelTrace, TraceStep
from .console import wide_console


def _rgb(c: tuple[float, float, float]) -> str:
    return "(" + ", ".join(f"{v:.4f}" for v in c) + ")"


def _xy(p: tuple[float, float] | None) -> str:
    return "-" if p is None else f"{p[0]:.2f}, {p[1]:.2f}"


def top_steps(trace: PixelTrace, n: int) -> list[TraceStep]:
    """The `n` entries that added the most to the pixel (weight share), over every sample."""
    return sorted((s for s in trace.steps if not s.rejected), key=lambda s: -s.weight)[:n]


def trace_table(trace: PixelTrace, top: int):
    """One mode's rich Table: its `top` contributors; the caption counts the rest."""
    from rich.table import Table

    steps = trace.steps
    multi = trace.supersample > 1
    window = bool(steps) and steps[0].window_center is not None
    duplex = bool(steps) and steps[0].cell is not None
    t = Table(
        title=f"{trace.mode}: pixel ({trace.x}, {trace.y}) of {trace.width}x{trace.height}, colour "
        f"{_rgb(trace.color)}, T {trace.transmittance:.4g}",
        title_justify="left",
    )
    cols = ["sample"] if multi else []
    cols += ["splat", "depth", "alpha", "weight", "T before", "T after", "colour"]
    cols += ["window centre", "window size"] if window else []
    cols += ["cell", "T_cell"] if duplex else []
    for col in cols:
        t.add_column(col, justify="left" if col in ("colour", "window centre", "window size") else "right")
    for s in top_steps(trace, top):
        row = [str(s.sample)] if multi else []
        row += [
            s.short,
            f"{s.depth:.4g}",
            f"{s.alpha:.4f}",
            f"{s.weight:.4f}",
            f"{s.T_before:.4f}",
            f"{s.T_after:.4f}",
            _rgb(s.color),
        ]
        row += [_xy(s.window_center) + (" (fallback)" if s.fallback else ""), _xy(s.window_size)] if window else []
        row += [str(s.cell), f"{s.T_cell:.4f}"] if duplex else []
        t.add_row(*row)
    added = sum(1 for s in steps if not s.rejected)
    rejected = Counter(trace.rejected_counts()).most_common()
    samples = f" over {len(trace.samples)} samples" if multi else ""
    t.caption = f"{len(steps)} list entries{samples}: {added} added (top {min(top, added)} shown), rejected: " + (
        ", ".join(f"{why} {k}" for why, k in rejected) or "none"
    )
    t.caption_justify = "left"
    return t


def print_traces(traces: list[PixelTrace], top: int) -> None:
    """A table per trace, then one line per mode with its colour and transmittance."""
    from rich.table import Table

    console = wide_console()
    for trace in traces:
        console.print(trace_table(trace, top))
    summary = Table(title="Pixel per mode (as rendered, background included)", title_justify="left")
    for col in ("mode", "colour", "T", "added", "largest weight"):
        summary.add_column(col, justify="left" if col in ("mode", "colour") else "right")
    for trace in traces:
        best = top_steps(trace, 1)
        summary.add_row(
            trace.mode,
            _rgb(trace.color),
            f"{trace.transmittance:.4g}",
            str(sum(1 for s in trace.steps if not s.rejected)),
            f"{best[0].weight:.4f} ({best[0].source})" if best else "-",
        )
    console.print(summary)


def write_traces(path: Path, traces: list[PixelTrace], scene: str, force: bool = False) -> Path:
    """Every trace as JSON: {"scene": scene, "traces": [PixelTrace.to_dict(), ...]} (each what PixelTrace.to_json
    gives: strict JSON, a non-finite number written null)."""
    doc = {"scene": scene, "traces": [t.to_dict() for t in traces]}
    return atomic_write(path, lambda p: p.write_text(dumps_json(doc)), force)


# TraceStep fields holding tuples: one CSV column per element, named field_suffix
_SPLIT = {
    "color": ("r", "g", "b"),
    "mean": ("x", "y"),
    "conic": ("a", "b", "c"),
    "covariance": ("xx", "xy", "yy"),
    "window_center": ("x", "y"),
    "window_size": ("w", "h"),
}
CSV_COLUMNS = ("pane", "mode", "x", "y", "supersample") + tuple(
    f"{f}_{s}" if f in _SPLIT else f for f in TraceStep._fields for s in _SPLIT.get(f, ("",))
)


def csv_rows(traces: list[tuple[str, PixelTrace]]) -> list[list]:
    """One row per step of every (pane, trace), CSV_COLUMNS in order: the pane's name, the trace's mode, pixel and
    supersampling, then the step's fields (tuples split into one column each; "" where a field does not apply)."""
    rows = []
    for pane, trace in traces:
        head = [pane, trace.mode, trace.x, trace.y, trace.supersample]
        for step in trace.steps:
            row = list(head)
            for f, v in zip(TraceStep._fields, step):
                if f in _SPLIT:
                    row += [""] * len(_SPLIT[f]) if v is None else list(v)
                else:
                    row.append("" if v is None else v)
            rows.append(row)
    return rows


def write_traces_csv(path: Path, traces: list[tuple[str, PixelTrace]], force: bool = False) -> Path:
    """The steps of every (pane, trace) as CSV (`csv_rows` under a CSV_COLUMNS header)."""
    import csv

    def write(p: Path) -> None:
        with open(p, "w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow(CSV_COLUMNS)
            out.writerows(csv_rows(traces))

    return atomic_write(path, write, force)
