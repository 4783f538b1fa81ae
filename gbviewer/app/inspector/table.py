"""The Inspector's table of a trace's steps (`view` draws the rest): the columns that fit the width
without scrolling sideways, chosen by what matters most (#, splat, weight, alpha, T after, note first); every row's
full values in its tooltip."""

from __future__ import annotations

from typing import Callable

from imgui_bundle import imgui

from ...render import PixelTrace, TraceStep
from .state import Entry, Inspector

Cell = Callable[[TraceStep], str]
# (header, the cell, a value as wide as the widest, priority: lower is kept first)
COLUMNS: tuple[tuple[str, Cell, str, int], ...] = (
    ("sample", lambda s: str(s.sample), "00", 8),
    ("splat", lambda s: s.short, "", 1),
    ("depth", lambda s: f"{s.depth:.4g}", "-0.000e+00", 6),
    ("alpha", lambda s: f"{s.alpha:.4f}", "0.0000", 3),
    ("weight", lambda s: f"{s.weight:.4f}", "0.0000", 2),
    ("T before", lambda s: f"{s.T_before:.4f}", "0.0000", 7),
    ("T after", lambda s: f"{s.T_after:.4f}", "0.0000", 4),
    ("window centre", lambda s: f"{s.window_center[0]:.3f}, {s.window_center[1]:.3f}", "-0.000, -0.000", 11),
    ("window size", lambda s: f"{s.window_size[0]:.3f} x {s.window_size[1]:.3f}", "0.000 x 0.000", 12),
    ("cell", lambda s: str(s.cell), "0000000", 9),
    ("T_cell", lambda s: f"{s.T_cell:.4f}", "0.0000", 10),
    ("note", lambda s: s.rejected or ("fallback" if s.fallback else ""), "", 5),
)


def describe(s: TraceStep, k: int) -> str:
    """Step k (0-based) in words, with every value the table has."""
    what = s.rejected or ("added" + (" (fallback)" if s.fallback else "") + (", stops the pixel" if s.stopped else ""))
    line = (
        f"#{k + 1} {s.source}  depth {s.depth:.4g}  {what}  alpha {s.alpha:.4f}  weight {s.weight:.4f}  "
        f"T {s.T_before:.4f} -> {s.T_after:.4f}"
    )
    if s.window_center is not None:
        line += (
            f"  window after: centre {s.window_center[0]:.3f}, {s.window_center[1]:.3f}  size "
            f"{s.window_size[0]:.3f} x {s.window_size[1]:.3f}"
        )
    if s.cell is not None:
        line += f"  cell {s.cell}  T_cell {s.T_cell:.4f}"
    return line


def columns(
    t: PixelTrace, steps: tuple, width: float, measure: Callable[[str], float], pad: float
) -> list[tuple[str, Cell]]:
    """The columns after "#" that fit `width` (each as wide as its header or widest value plus `pad`; at least
    one), in table order."""
    s0 = steps[0]
    present = [
        c
        for c in COLUMNS
        if (c[0] != "sample" or t.supersample > 1)
        and (c[0] not in ("window centre", "window size") or s0.window_center is not None)
        and (c[0] not in ("cell", "T_cell") or s0.cell is not None)
    ]
    widest = {
        "splat": max((s.short for s in steps), key=len),
        "note": max((r for r in (*t.rejected_counts(), "fallback")), key=measure),
    }
    used = measure(str(len(steps))) + pad
    kept = []
    for c in sorted(present, key=lambda c: c[3]):
        w = max(measure(c[0]), measure(widest.get(c[0], c[2]))) + pad
        if used + w <= width or not kept:
            used += w
            kept.append(c)
    return [(c[0], c[1]) for c in present if c in kept]


def draw_table(insp: Inspector, e: Entry, t: PixelTrace, steps: tuple, current: int) -> None:
    """Every shown step, one row each (clicking one moves the slider to it, hovering shows all its values),
    scrolled with a clipper; sideways only where even the first columns do not fit."""
    style = imgui.get_style()
    avail = imgui.get_content_region_avail()
    pad = 2 * style.cell_padding.x + 1  # a cell's padding and the inner border
    cols = columns(t, steps, avail.x - style.scrollbar_size - 2, lambda x: imgui.calc_text_size(x).x, pad)
    rows = insp.order(t, insp.options.by_weight)
    flags = (
        imgui.TableFlags_.scroll_y
        | imgui.TableFlags_.scroll_x
        | imgui.TableFlags_.row_bg
        | imgui.TableFlags_.borders_inner_v
        | imgui.TableFlags_.sizing_fixed_fit
    ).value
    if not imgui.begin_table("##steps", len(cols) + 1, flags, (0, max(90.0, avail.y))):
        return
    imgui.table_setup_scroll_freeze(0, 1)
    imgui.table_setup_column("#")
    for name, _ in cols:
        imgui.table_setup_column(name)
    imgui.table_headers_row()
    clipper = imgui.ListClipper()
    clipper.begin(len(rows))
    span = (imgui.SelectableFlags_.span_all_columns | imgui.SelectableFlags_.allow_overlap).value
    while clipper.step():
        for k in rows[clipper.display_start : clipper.display_end]:
            s = steps[k]
            imgui.table_next_row()
            imgui.table_next_column()
            if imgui.selectable(f"{k + 1}##{k}", k == current, span)[0]:
                insp.options.step[e.slot] = k
            if imgui.is_item_hovered():
                tooltip(describe(s, k))
            for _, cell in cols:
                imgui.table_next_column()
                imgui.text(cell(s))
    clipper.end()
    imgui.end_table()


def tooltip(text: str) -> None:
    """A tooltip wrapped at 36 characters' width."""
    imgui.begin_tooltip()
    imgui.push_text_wrap_pos(imgui.get_font_size() * 36)
    imgui.text_unformatted(text)
    imgui.pop_text_wrap_pos()
    imgui.end_tooltip()
