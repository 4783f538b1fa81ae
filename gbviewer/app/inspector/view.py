"""The pixel inspector drawn with imgui (`inspector.Inspector` holds its state): the pinned pixel outlined on every
pane, and the Inspector window with the traces of the pane parts side by side (or one alone): per pane the rendered
colour and T, the list entries and rejections by reason, a drawing of the pixel square with the splats' ellipses at
their cut-off (gaussian_blending: the transmittance window after each step) stepped through with a slider, and a
table of the steps (largest weight first, or in blend order); buttons export the traces as JSON and CSV."""

from __future__ import annotations

import math
from bisect import bisect_left
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from ...render import PixelTrace
from ..overlays.labels import GREY, WHITE, YELLOW, col
from ..ui.keys import hint
from .state import Entry, Inspector, pixel_box, render_pixel
from .table import describe, draw_table

if TYPE_CHECKING:
    from ..window import ViewerApp

MARK_MIN = 7.0  # display pixels: the outline of a smaller render pixel (zoomed in) is drawn this big around it
CANVAS_MAX = 300.0
TOP_DRAWN = 8  # contributors drawn in their colour (the others faintly)
WINDOW_COLOUR, PATH_COLOUR, BLACK = col(80, 230, 255), col(80, 230, 255, 140), col(0, 0, 0, 200)


MIN_COLUMN_W = 320  # narrower trace columns stack into rows (the window scrolls)


def dock_side(app: ViewerApp) -> str | None:
    """Where the Inspector docks while a pixel is pinned: right of a single pane (its traces stack in rows), below
    two or more (one trace column per pane part where the width allows, else stacked rows); None unpinned."""
    if app.inspector.pin is None or app.state.scene is None:
        return None
    return "right" if app.state.settings.pane_count == 1 else "below"


def draw_inspector(app: ViewerApp) -> None:
    """The pin's marks on the panes and, while a pixel is pinned, the Inspector window docked in the area the
    panes made room for (`AppState.dock_rect`; its close box unpins)."""
    insp, dock = app.inspector, app.state.dock_rect
    draw_pin_marks(app)
    if insp.pin is None or dock is None:
        return
    imgui.set_next_window_pos((dock.x + 4, dock.y + 2))
    imgui.set_next_window_size((dock.w - 8, dock.h - 4))
    flags = (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse).value
    expanded, keep = imgui.begin("Inspector", True, flags)
    if expanded:
        _contents(app, insp)
    imgui.end()
    if not keep:
        insp.unpin()


def draw_pin_marks(app: ViewerApp) -> None:
    """An outline around the pinned render pixel of every visible pane (at its render size at the current rate)."""
    state, pin = app.state, app.inspector.pin
    if pin is None or state.scene is None:
        return
    dl = imgui.get_background_draw_list()
    for p in state.visible:
        r = p.rect
        w, h = p.render_size
        x0, y0, x1, y1 = pixel_box(r, *render_pixel(*pin, w, h), w, h)
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        hx, hy = max(x1 - x0, MARK_MIN) / 2 + 1.5, max(y1 - y0, MARK_MIN) / 2 + 1.5  # just outside the pixel
        dl.push_clip_rect((r.x, r.y), (r.x + r.w, r.y + r.h), True)
        dl.add_rect((cx - hx - 1, cy - hy - 1), (cx + hx + 1, cy + hy + 1), BLACK, 0.0, 1.5)
        dl.add_rect((cx - hx, cy - hy), (cx + hx, cy + hy), YELLOW, 0.0, 1.5)
        dl.pop_clip_rect()


def _contents(app: ViewerApp, insp: Inspector) -> None:
    o = insp.options
    entries = insp.entries()
    names = {e.slot: f"{e.name} {e.trace.mode if e.trace is not None else ''}".strip() for e in entries}
    if o.alone not in names:
        o.alone = None
    right = imgui.get_cursor_screen_pos().x + imgui.get_content_region_avail().x
    imgui.set_next_item_width(min(240.0, imgui.get_content_region_avail().x))
    if imgui.begin_combo("##alone", "panes side by side" if o.alone is None else f"pane {names[o.alone]}"):
        if imgui.selectable("panes side by side", o.alone is None)[0]:
            o.alone = None
        for slot, name in names.items():
            if imgui.selectable(f"pane {name}", o.alone == slot)[0]:
                o.alone = slot
        imgui.end_combo()
    _flow(right, "all list entries", box=True)
    o.show_all = imgui.checkbox("all list entries", o.show_all)[1]
    if imgui.is_item_hovered():
        imgui.set_tooltip("also the entries skipped by the splat's box (outside_box), never evaluated")
    _flow(right, "largest weight first", box=True)
    o.by_weight = imgui.checkbox("largest weight first", o.by_weight)[1]
    for k, label in enumerate(("Export JSON", "Export CSV", f"Unpin ({hint('toggle_pin')})")):
        if k:
            _flow(right, label)
        if imgui.button(label):
            (insp.export_json, insp.export_csv, insp.unpin)[k]()
            if k == 2:
                return
    _flow(right, "Ctrl+click a pane to pin another pixel", plain=True)
    imgui.text_disabled("Ctrl+click a pane to pin another pixel")
    shown = [e for e in entries if o.alone is None or e.slot == o.alone]
    gap, avail = imgui.get_style().item_spacing.x, imgui.get_content_region_avail()
    cols = max(1, min(len(shown), int((avail.x + gap) // (MIN_COLUMN_W + gap))))  # stacked rows when narrow
    rows = -(-len(shown) // cols)
    height = 0 if rows == 1 else max(260.0, (avail.y - gap * (rows - 1)) / rows)
    bar = imgui.get_style().scrollbar_size if rows * height + gap * (rows - 1) > avail.y else 0.0  # scrolls down
    width = (avail.x - bar - gap * (cols - 1)) / cols
    imgui.begin_child("##traces", (0, 0))
    for k, e in enumerate(shown):
        if k % cols:
            imgui.same_line()
        imgui.begin_child(f"##trace{e.slot}", (width, height), imgui.ChildFlags_.borders.value)
        _entry(app, insp, e)
        imgui.end_child()
    imgui.end_child()


def _flow(right: float, label: str, box: bool = False, plain: bool = False) -> None:
    """Put the next item (a button, a checkbox with `box`, text with `plain`, labelled `label`) on the same line
    as the last when it fits before `right`, else on the next line."""
    style = imgui.get_style()
    w = imgui.calc_text_size(label).x + (0 if plain else 2 * style.frame_padding.x)
    if box:
        w += imgui.get_frame_height() + style.item_inner_spacing.x - 2 * style.frame_padding.x
    if imgui.get_item_rect_max().x + style.item_spacing.x + w <= right:
        imgui.same_line()


def _entry(app: ViewerApp, insp: Inspector, e: Entry) -> None:
    t = e.trace
    if t is None:
        why = (
            e.result.error
            if e.result is not None
            else ("tracing..." if e.pixel is not None else "waiting for the pane's final frame")
        )
        imgui.text(f"{e.name}  {app.state.settings_for(*e.slot).label}")
        imgui.text_disabled(why)
        return
    imgui.text(f"{e.name}  {t.mode}")
    imgui.push_style_color(imgui.Col_.text.value, imgui.get_style().color_(imgui.Col_.text_disabled.value))
    imgui.text_wrapped(
        f"pixel ({t.x}, {t.y}) of {t.width}x{t.height}"
        + (f", {t.supersample}x{t.supersample} samples" if t.supersample > 1 else "")
        + ("  (stale)" if e.stale else "")
    )
    imgui.pop_style_color()
    steps = insp.steps(t)
    blend = insp.slider_steps(t)
    pos = min(bisect_left(blend, insp.options.step.get(e.slot, 0)), max(0, len(blend) - 1))  # the nearest shown
    if blend:  # the drawing on the left, the numbers and the slider on its right, the table below
        avail = imgui.get_content_region_avail()
        _canvas(insp, t, steps, blend, pos, max(120.0, min(CANVAS_MAX, avail.x * 0.42, avail.y - 110)))
        imgui.same_line()
    imgui.begin_group()
    r, g, b = (min(1.0, max(0.0, c)) for c in t.color)
    imgui.color_button("##colour", imgui.ImVec4(r, g, b, 1.0), imgui.ColorEditFlags_.no_tooltip.value, (22, 22))
    imgui.same_line()
    imgui.text_wrapped(f"RGB {t.color[0]:.4f} {t.color[1]:.4f} {t.color[2]:.4f}   T {t.transmittance:.4g}")
    added = sum(1 for s in steps if not s.rejected)
    rejected = sorted(t.rejected_counts().items(), key=lambda kv: -kv[1])
    imgui.text_wrapped(
        f"{len(steps)} list entries, {added} added; rejected: "
        + (", ".join(f"{why} {n}" for why, n in rejected) or "none")
    )
    if e.result is not None and e.result.request.backend != insp.thread.backend:
        imgui.text_disabled(
            f"traced on the {insp.thread.backend} kernel (the pane renders on {e.result.request.backend})"
        )
    if blend:
        imgui.set_next_item_width(-1)
        changed, value = imgui.slider_int("##step", pos + 1, 1, len(blend), f"step %d/{len(blend)}: #{blend[pos] + 1}")
        if imgui.is_item_hovered():
            imgui.set_tooltip(
                "the steps in blend order: those that added to the pixel (all list entries: every "
                "one); #: the entry's number in the list, as in the table"
            )
        if changed:
            pos = value - 1
            insp.options.step[e.slot] = blend[pos]
        imgui.text_wrapped(describe(steps[blend[pos]], blend[pos]))
    else:
        imgui.text_disabled("no list entries here (all list entries shows the skipped ones)")
    imgui.end_group()
    if blend:
        draw_table(insp, e, t, steps, blend[pos])


def _canvas(insp: Inspector, t: PixelTrace, steps: tuple, blend: list[int], pos: int, side: float) -> None:
    """The pixel square and a margin around it (options.margin), enlarged to `side` display pixels: the added
    splats' ellipses at their cut-off (the TOP_DRAWN largest weights in their colour, the others faint, the current
    step's in yellow with its centre), the sample positions, and for gaussian_blending the window after the current
    step and the path of its centre."""
    p0 = imgui.get_cursor_screen_pos()
    imgui.invisible_button("##canvas", (side, side))
    if imgui.is_item_hovered():
        insp.zoom(imgui.get_io().mouse_wheel)
        imgui.set_tooltip(f"{1 + 2 * insp.options.margin:.3g} pixels across; the wheel zooms")
    dl = imgui.get_window_draw_list()
    margin = insp.options.margin
    scale = side / (1 + 2 * margin)
    ox, oy = t.x - margin, t.y - margin

    def at(x: float, y: float) -> tuple[float, float]:
        return p0.x + (x - ox) * scale, p0.y + (y - oy) * scale

    dl.push_clip_rect(p0, (p0.x + side, p0.y + side), True)
    dl.add_rect_filled(p0, (p0.x + side, p0.y + side), col(16, 17, 20))
    r, g, b = (round(min(1.0, max(0.0, c)) * 255) for c in t.color)
    dl.add_rect_filled(at(t.x, t.y), at(t.x + 1, t.y + 1), col(r, g, b, 90))
    n = math.ceil(margin)
    if n <= 8:  # the pixel grid around the pinned pixel
        for k in range(-n, n + 2):
            dl.add_line(at(t.x + k, oy), at(t.x + k, oy + 1 + 2 * margin), col(70, 72, 80))
            dl.add_line(at(ox, t.y + k), at(ox + 1 + 2 * margin, t.y + k), col(70, 72, 80))
    dl.add_rect(at(t.x, t.y), at(t.x + 1, t.y + 1), WHITE, 0.0, 2.0)
    current = blend[pos]
    top = set(insp.order(t, by_weight=True)[:TOP_DRAWN])
    for k in sorted(blend, key=lambda k: (k == current, k in top)):  # the current step's on top
        s = steps[k]
        if s.rejected and k != current:
            continue
        pts = insp.ellipse(t, k)
        if pts is None:
            continue
        sr, sg, sb = (round(min(1.0, max(0.0, c)) * 255) for c in s.color)
        colour, width = (
            (YELLOW, 3.0) if k == current else (col(sr, sg, sb, 210), 1.5) if k in top else (col(sr, sg, sb, 45), 1.0)
        )
        dl.add_polyline(
            [imgui.ImVec2(*at(*p)) for p in pts], col=colour, thickness=width, flags=imgui.ImDrawFlags_.closed.value
        )
    s = steps[current]
    mx, my = at(*s.mean)  # its centre; out of view: a ring on the edge towards it
    inside = p0.x <= mx <= p0.x + side and p0.y <= my <= p0.y + side
    if inside:
        dl.add_circle_filled((mx, my), 4.0, YELLOW)
    elif math.isfinite(mx) and math.isfinite(my):
        dl.add_circle(
            (min(max(mx, p0.x + 6), p0.x + side - 6), min(max(my, p0.y + 6), p0.y + side - 6)), 5.0, YELLOW, 0, 2.0
        )
    if s.window_center is not None:  # the window's centre, pixel to now (this sample), and the window now
        path = [at(*t.samples[s.sample].position)] + [
            at(*steps[k].window_center) for k in blend[: pos + 1] if steps[k].sample == s.sample
        ]
        if len(path) > 1:
            dl.add_polyline([imgui.ImVec2(*q) for q in path], col=PATH_COLOUR, thickness=1.5, flags=0)
        (cx, cy), (w, h) = s.window_center, s.window_size
        dl.add_rect(at(cx - w / 2, cy - h / 2), at(cx + w / 2, cy + h / 2), WINDOW_COLOUR, 0.0, 2.0)
    for sample in t.samples:
        dl.add_circle_filled(at(*sample.position), 2.5, WHITE if sample is t.samples[s.sample] else GREY)
    dl.pop_clip_rect()
