"""The one layout rule for text over the panes: each pane part (a whole pane, or one half of a split) has one label
line at its top and at most one message line under it, and the information lines at its bottom, all inside the
part's own box, each measured (a `Measure`: imgui.calc_text_size in the window) and elided with '…' where it does
not fit (its full text then is the tooltip); information lines that do not fit between the message line and the
bottom are left out. Banners wrap. No imgui here: tests/app/test_pane_text.py checks that nothing overlaps."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

from .layout import Rect

Measure = Callable[[str], tuple[float, float]]  # text -> (width, height) in window units
PAD = 4  # between a box's edge and its text, and around each text's dark background
ELLIPSIS = "…"


@dataclass(frozen=True)
class Item:
    """A text placed over a pane: its background box (x, y, w, h), the text drawn, the full text, its role."""

    x: float
    y: float
    w: float
    h: float
    text: str
    full: str
    role: str  # "label", "message", "info", "banner"
    colour: int = 0

    @property
    def elided(self) -> bool:
        return self.text != self.full

    def overlaps(self, other: Item) -> bool:
        return (
            self.x < other.x + other.w
            and other.x < self.x + self.w
            and self.y < other.y + other.h
            and other.y < self.y + self.h
        )

    def inside(self, box: Rect) -> bool:
        return (
            box.x <= self.x
            and self.x + self.w <= box.x + box.w
            and box.y <= self.y
            and self.y + self.h <= box.y + box.h
        )


def elide(text: str, width: float, measure: Measure) -> str:
    """`text`, or its longest start that with '…' measures at most `width` ('' when not even '…' fits)."""
    if measure(text)[0] <= width:
        return text
    lo, hi = 0, len(text)  # binary search over the kept prefix's length
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if measure(text[:mid].rstrip() + ELLIPSIS)[0] <= width:
            lo = mid
        else:
            hi = mid - 1
    if lo == 0 and measure(ELLIPSIS)[0] > width:
        return ""
    return text[:lo].rstrip() + ELLIPSIS


def wrap(text: str, width: float, measure: Measure) -> list[str]:
    """`text` broken at spaces into lines that measure at most `width` (a word longer than that is elided)."""
    lines: list[str] = []
    for word in text.split():
        if lines and measure(f"{lines[-1]} {word}")[0] <= width:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word if measure(word)[0] <= width else elide(word, width, measure))
    return lines or [""]


def _item(x: float, y: float, text: str, role: str, colour: int, width: float, measure: Measure) -> Item | None:
    shown = elide(text, width - 2 * PAD, measure)
    if not shown:
        return None
    w, h = measure(shown)
    return Item(x, y, w + 2 * PAD, h + PAD, shown, text, role, colour)


def lay_out_part(
    box: Rect, label: tuple[str, int], message: tuple[str, int] | None, info: list[tuple[str, int]], measure: Measure
) -> tuple[list[Item], float]:
    """The items of one pane part in `box` (label, message, info lines bottom up) and the y below its top lines
    (where a colour bar may go)."""
    items: list[Item] = []
    x, y, width = box.x + PAD, box.y + PAD, box.w - 2 * PAD
    line_h = measure("Ag")[1] + PAD
    for line, role in ((label, "label"), (message, "message")):
        if line is None or y + line_h > box.y + box.h:
            continue
        item = _item(x, y, line[0], role, line[1], width, measure)
        if item is not None:
            items.append(item)
            y += item.h + 2
    bottom = box.y + box.h - PAD
    for text, colour in reversed(info):
        if bottom - line_h < y:
            break  # no room left above: the rest of the information lines are left out
        item = _item(x, bottom - line_h, text, "info", colour, width, measure)
        if item is not None:
            items.append(item)
            bottom -= line_h + 2
    return items, y


def lay_out_banner(area: Rect, text: str, y: float, colour: int, measure: Measure) -> list[Item]:
    """A banner centred in `area` from y down (moved up as far as it must to end inside it), wrapped to its width
    (each line its own item)."""
    out = []
    for line in wrap(text, area.w - 8 * PAD, measure):
        w, h = measure(line)
        out.append(
            Item(area.x + max(PAD, (area.w - w) / 2 - PAD), y, w + 2 * PAD, h + PAD, line, line, "banner", colour)
        )
        y += h + PAD + 2
    over = max(0.0, out[-1].y + out[-1].h - (area.y + area.h - PAD))
    return [replace(i, y=max(area.y + PAD, i.y - over)) for i in out]
