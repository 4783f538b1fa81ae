"""What is drawn over the panes with the imgui draw lists: each pane part's label (with its view's legend), its one
message line (error, preview, refining or PSNR), its statistics lines (`ui.text` places them), the split divider,
loading and error banners (wrapped), the magnifier loupe; and the status bar."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable

from imgui_bundle import imgui

from ...io.trained_as import describe
from ...model.camera import format_rate
from ...render import AUTO
from ...render.presets import trained_spec
from ..difference.views import shows_photo
from ..frames.accumulate import is_stochastic
from ..pane_state import PaneState
from ..panes import pane_fps
from ..ui.keys import hint
from ..ui.layout import Rect, loupe_uv
from ..ui.text import PAD, Item, lay_out_banner, lay_out_part

if TYPE_CHECKING:
    from ..window import ViewerApp


def col(r: int, g: int, b: int, a: int = 255) -> int:
    """An imgui draw-list colour."""
    return (a << 24) | (b << 16) | (g << 8) | r


WHITE, BLACK_A, YELLOW, RED, GREY, ACCENT = (
    col(255, 255, 255),
    col(0, 0, 0, 170),
    col(255, 205, 60),
    col(255, 90, 80),
    col(150, 150, 150),
    col(90, 170, 255),
)
LEVEL_COLOURS = {"info": WHITE, "warn": YELLOW, "error": RED}
FLY_HINT = "fly: WASD QE move, drag looks, {} ends"


def measure(app: ViewerApp) -> Callable[[str], tuple[float, float]]:
    """The size of a text in the overlays' font (push it first: `mono`)."""

    def size(s: str) -> tuple[float, float]:
        v = imgui.calc_text_size(s)
        return v.x, v.y

    return size


class mono:
    """`with mono(app):` the overlays' monospace font."""

    def __init__(self, app: ViewerApp) -> None:
        self.font = app.mono

    def __enter__(self) -> None:
        if self.font is not None:
            imgui.push_font(self.font, 15.0)

    def __exit__(self, *exc) -> None:
        if self.font is not None:
            imgui.pop_font()


def draw_item(app: ViewerApp, dl, item: Item, bg: int = BLACK_A) -> None:
    """A placed text on its dark box (the font pushed), recorded in app.placed; its full text as the tooltip when
    it was elided and the cursor is on it."""
    dl.add_rect_filled((item.x, item.y), (item.x + item.w, item.y + item.h), bg, 3.0)
    dl.add_text((item.x + PAD, item.y + PAD / 2), item.colour, item.text)
    app.placed.append(item)
    m = imgui.get_io().mouse_pos
    if item.elided and item.x <= m.x < item.x + item.w and item.y <= m.y < item.y + item.h:
        imgui.set_tooltip(item.full)


def banner(app: ViewerApp, dl, s: str, y: float, colour: int) -> None:
    """Text centred on the panes from y down, wrapped to their width."""
    with mono(app):
        for item in lay_out_banner(app.state.viewport, s, y, colour, measure(app)):
            draw_item(app, dl, item, col(0, 0, 0, 220))


def pane_label(app: ViewerApp, p: PaneState, part: str) -> str:
    """'A  scalar  x1/4  106x186': pane, mode (as rendered), rate, render size, debug view; showing the photo:
    'A  photo v00  x1/4  32x25'."""
    state = app.state
    ps = state.settings.panes[p.index]
    shown = p.parts[part]
    job = shown.job
    if job is None:  # nothing rendered yet: what it will be
        w, h = p.render_size
        return (
            f"{p.name}{chr(39) if part == 'b' else ''}  {ps.mode if part == 'a' else ps.split_mode}  "
            f"{format_rate(state.settings.rate)}  {w}x{h}"
        )
    label = job.settings.label_for(state.scene) if state.scene is not None else job.settings.label
    if state.scene is not None and job.settings.name == trained_spec(state.scene.meta):
        label += f" (as trained: {describe(state.scene.meta)})"
    if is_stochastic(job.settings):  # the running mean's samples per pixel (accumulate)
        label += f" {shown.accumulation.samples(job.settings.supersample)} spp"
    rate = format_rate(job.info.get("rate", state.settings.rate))
    w, h = job.info.get("full_size", (job.camera.width, job.camera.height))
    name = p.name + ("'" if part == "b" else "")
    if shows_photo(shown):
        return f"{name}  {shown.legend}"
    view = f"  [{shown.view}]" if shown.view and shown.view != "color" else ""
    return f"{name}  {label}  {rate}  {w}x{h}{view}"


def stats_lines(p: PaneState, part: str) -> list[str]:
    """The information overlay of a pane part (none while it shows the photo): timings per stage, fps, visible
    splats, evaluations per pixel, and the pacing of its last requests (ms from the request to the preview, to the
    first full-resolution tiles, to the final frame)."""
    shown = p.parts[part]
    if shows_photo(shown):
        return []  # (no render on screen: its timings would describe something else)
    st = shown.frame.stats
    tag = f"{p.name}' " if part == "b" else ""
    lines = [
        f"{tag}{st.total_ms:.1f} ms: pre {st.preprocess_ms:.1f} + sort {st.sort_ms:.1f} + blend "
        f"{st.blend_ms:.1f}  {pane_fps(p, part):.1f} fps",
        f"{tag}{st.visible:,} splats visible  {st.evals_per_pixel:.0f} evals/px",
    ]
    if shown.pacing:
        names = {"preview": "preview", "tiles": "first tiles", "final": "final"}
        lines.append(tag + "  ".join(f"{names[k]} {v:.0f} ms" for k, v in shown.pacing.items()))
    return lines


def part_box(r: Rect, split: bool, split_pos: float, part: str) -> Rect:
    """The box of a pane part: the whole pane, or its half of a split (left of the divider for 'a')."""
    if not split:
        return r
    sx = r.x + min(1.0, max(0.0, split_pos)) * r.w
    return Rect(r.x, r.y, sx - r.x, r.h) if part == "a" else Rect(sx, r.y, r.x + r.w - sx, r.h)


def message(app: ViewerApp, p: PaneState, part: str) -> tuple[str, int] | None:
    """A pane part's one message line: its error, else (the first pane, in fly mode) the fly keys, else what it
    waits for before its first tiles (`PaneRenders.progress`), else its preview or refining state, else its
    PSNR/SSIM line."""
    shown, job = p.parts[part], p.parts[part].job
    if shown.error is not None:
        return shown.error.text, RED
    if app.state.fly and p.index == 0 and part == "a":
        return FLY_HINT.format(hint("toggle_fly")), ACCENT
    waiting = app.panes.progress(p.index, part)
    if waiting is not None:
        return waiting, YELLOW
    if job is not None and job.info.get("preview", 1.0) < 1.0:
        fw, fh = job.info["full_size"]
        return f"moving: preview {job.camera.width}x{job.camera.height} (not {fw}x{fh})", YELLOW
    if shown.progress is not None:
        return f"{'x1 sample shown, refining' if shown.stage == 'quick' else 'refining'} {shown.progress:.0%}", YELLOW
    line = app.analysis.fidelity_line((p.index, part))
    if line is not None:
        return line[0], GREY if line[1] else WHITE
    if app.worker.busy((p.index, part)) and job is not None:
        return "rendering...", GREY
    return None


def draw_pane_overlays(app: ViewerApp) -> None:
    """Each pane part's label (with its view's legend), one message line and, with the info overlay, its statistics,
    laid out by `ui.text.lay_out_part` inside the part's box; the split divider; the load banners."""
    state = app.state
    dl = imgui.get_background_draw_list()
    v = state.viewport
    app.placed, app.part_tops = [], {}
    if state.loader is not None:  # over the previous scene, which stays until the new one is ready
        ld = state.loader
        y = v.y + v.h / 2 if state.scene is None else v.y + 40
        banner(app, dl, f"loading {ld.path.name}: {ld.describe()}, {ld.elapsed:.1f} s (Esc cancels)", y, WHITE)
    if state.scene is None:
        return
    with mono(app):
        for p in state.visible:
            r = p.rect
            ps = state.settings.panes[p.index]
            dl.push_clip_rect((r.x, r.y), (r.x + r.w, r.y + r.h), True)
            if ps.split:
                sx = r.x + ps.split_pos * r.w
                dl.add_line((sx, r.y), (sx, r.y + r.h), col(255, 255, 255, 220), 2.0)
                dl.add_circle_filled((sx, r.y + r.h / 2), 7, col(255, 255, 255, 230))
                dl.add_circle((sx, r.y + r.h / 2), 7, col(0, 0, 0, 200), 0, 1.5)
            for part in state.parts(p.index):
                shown = p.parts[part]
                label = pane_label(app, p, part)
                if shown.legend and not shows_photo(shown):  # (the photo's legend is its label)
                    label = f"{label}  {shown.legend}"
                info = (
                    [(line, col(220, 220, 220)) for line in stats_lines(p, part)]
                    if state.settings.show_info and shown.frame is not None
                    else []
                )
                box = part_box(r, ps.split, ps.split_pos, part)
                items, below = lay_out_part(box, (label, WHITE), message(app, p, part), info, measure(app))
                for item in items:
                    draw_item(app, dl, item)
                app.part_tops[(p.index, part)] = below
            if state.hover is not None and state.hover[0] == p.index:
                dl.add_rect((r.x, r.y), (r.x + r.w, r.y + r.h), col(90, 170, 255, 120), 0.0, 1.0)
            dl.pop_clip_rect()
    if state.load_error:
        banner(app, dl, state.load_error_short or state.load_error, v.y + v.h - 90, RED)


def draw_status(app: ViewerApp) -> None:
    """The bottom bar: rate, render sizes, backend, camera mode, the latest message."""
    state, s = app.state, app.state.settings
    io = imgui.get_io()
    h = imgui.get_frame_height() + 6
    imgui.set_next_window_pos((0, io.display_size.y - h))
    imgui.set_next_window_size((io.display_size.x, h))
    flags = (
        imgui.WindowFlags_.no_decoration
        | imgui.WindowFlags_.no_move
        | imgui.WindowFlags_.no_inputs
        | imgui.WindowFlags_.no_saved_settings
    ).value
    imgui.push_style_var(imgui.StyleVar_.window_padding.value, imgui.ImVec2(8, 3))
    imgui.begin("##status", None, flags)
    sizes = "  ".join(f"{p.name} {p.render_size[0]}x{p.render_size[1]}" for p in state.visible)
    backend = app.worker.backend_for(s.backend)
    simd = next(
        (
            part.frame.stats.simd
            for p in state.visible
            for part in p.parts.values()
            if part.frame is not None and part.frame.stats.simd
        ),
        "",
    )
    if app.worker.capabilities(backend).simd and simd:
        backend = f"{backend} {simd}"  # the blend's SIMD path (GBVIEWER_SIMD forces one)
    if s.backend == AUTO:
        backend += " (auto)"
    imgui.text(f"rate {format_rate(s.rate)}")
    imgui.same_line(0, 16)
    imgui.text_disabled(f"render {sizes}")
    imgui.same_line(0, 16)
    imgui.text_disabled(
        f"{backend} | display {app.worker.display_path(app.worker.backend_for(s.backend))[0]} | "
        f"{'fly' if state.fly else 'orbit'} | up {s.up} | "
        f"fov {state.controller.fov_y_deg:.0f}{' ortho' if s.projection == 'orthographic' else ''}"
    )
    now = time.perf_counter()
    recent = [m for m in state.messages if now - m[0] < 8.0]
    if recent:
        _, message, level = recent[-1]
        colour = LEVEL_COLOURS[level]
        imgui.same_line(0, 24)
        c = imgui.ImVec4((colour & 255) / 255, ((colour >> 8) & 255) / 255, ((colour >> 16) & 255) / 255, 1)
        imgui.text_colored(c, message)
    imgui.end()
    imgui.pop_style_var()


def draw_loupe(app: ViewerApp) -> None:
    """The magnifier: each visible pane's pixels around the cursor, side by side next to it."""
    state = app.state
    if not state.settings.loupe or state.hover is None:
        return
    io = imgui.get_io()
    dl = imgui.get_foreground_draw_list()
    _, u, v = state.hover
    n = state.settings.pane_count
    side = 160 if n <= 2 else 120
    radius = side / 2
    zoom = state.settings.loupe_zoom
    mx, my = io.mouse_pos.x, io.mouse_pos.y
    total_w = n * (side + 6)
    x = mx + 24 if mx + 24 + total_w < io.display_size.x else mx - 24 - total_w
    y = my + 24 if my + 24 + side + 24 < io.display_size.y else my - 24 - side - 24
    for k, p in enumerate(state.visible):
        ps = state.settings.panes[p.index]
        part = "b" if ps.split and u > ps.split_pos else "a"
        shown = p.parts[part]
        x0 = x + k * (side + 6)
        dl.add_rect_filled((x0 - 3, y - 3), (x0 + side + 3, y + side + 22), col(20, 22, 26, 240), 3.0)
        dl.add_rect((x0 - 2, y - 2), (x0 + side + 2, y + side + 2), col(170, 175, 185), 0.0, 2.0)
        if shown.texture is not None:
            u0, v0, u1, v1 = loupe_uv(u, v, p.rect.w, p.rect.h, radius, zoom)
            app.blit_loupe.add(shown.texture, x0, y, x0 + side, y + side, (u0, v0, u1, v1))
            cx = x0 + (u - u0) / (u1 - u0) * side  # the cursor: tick marks on the frame (the image covers
            cy = y + (v - v0) / (v1 - v0) * side  # the inside, it is drawn after the UI)
            dl.add_line((cx, y - 2), (cx, y - 8), col(255, 80, 80), 2.0)
            dl.add_line((x0 - 2, cy), (x0 - 8, cy), col(255, 80, 80), 2.0)
        mode = ps.split_mode if part == "b" else ps.mode
        label = f"{p.name}{chr(39) if part == 'b' else ''} {mode}"
        while len(label) > 3 and imgui.calc_text_size(label).x > side - 6:
            label = label[:-2] + "."
        dl.add_text((x0 + 3, y + side + 3), WHITE, label)
