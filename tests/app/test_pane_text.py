"""The layout rule for text over panes (app/ui/text.py), without a window: one label and at most one message line
per pane part inside its box, information lines from the bottom only where they fit, elided with '…' by measured
width, never overlapping; banners wrap inside the panes."""

from __future__ import annotations

import itertools

from gbviewer.app.overlays.labels import part_box
from gbviewer.app.ui.layout import Rect
from gbviewer.app.ui.text import ELLIPSIS, elide, lay_out_banner, lay_out_part, wrap


def measure(s: str) -> tuple[float, float]:
    """A monospace font of 8 x 15 units a character ('…' one character too)."""
    return 8.0 * len(s), 15.0


def test_elide_keeps_what_fits():
    assert elide("scalar", 48, measure) == "scalar"
    assert elide("A  gaussian_blending  x1/4", 80, measure) == "A  gaussi" + ELLIPSIS  # 10 characters
    assert measure(elide("x" * 100, 77, measure))[0] <= 77
    assert elide("abc", 4, measure) == ""


def test_wrap_breaks_at_spaces_within_the_width():
    lines = wrap("could not open bad.ply: not a PLY file (no 'ply' magic)", 120, measure)
    assert all(measure(line)[0] <= 120 for line in lines) and " ".join(lines).startswith("could not open")
    assert len(lines) > 1


def test_pane_parts_never_overlap_and_stay_in_their_boxes():
    label = ("B'  gaussian_blending  x1/4  187x125  [difference]  B - A (scalar)", 0)
    msg = ("photo: the camera left v00.png ([ ] to snap back)", 0)
    info = [
        ("12.1 ms: pre 1.0 + sort 2.0 + blend 9.1  30.0 fps", 0),
        ("1,234 splats visible  12 evals/px", 0),
        ("preview 10 ms  first tiles 20 ms  final 90 ms", 0),
    ]
    for w, h, split in itertools.product((90, 187, 400), (40, 80, 300), (None, 0.3, 0.5, 0.95)):
        r = Rect(10, 20, w, h)
        items = []
        for part in ("a", "b") if split is not None else ("a",):
            box = part_box(r, split is not None, split or 0.5, part)
            placed, _ = lay_out_part(box, label, msg, info, measure)
            assert all(i.inside(box) for i in placed)
            assert [i.role for i in placed].count("label") <= 1 and [i.role for i in placed].count("message") <= 1
            assert all(i.full.startswith(i.text.rstrip(ELLIPSIS)) for i in placed)
            items += placed
        for a, b in itertools.combinations(items, 2):
            assert not a.overlaps(b), (w, h, split, a, b)
    box = Rect(0, 0, 600, 300)  # room for everything: nothing elided, every information line shown
    placed, below = lay_out_part(box, label, msg, info, measure)
    assert [i.role for i in placed] == ["label", "message", "info", "info", "info"]
    assert not any(i.elided for i in placed)
    assert below == placed[1].y + placed[1].h + 2


def test_a_banner_wraps_and_ends_inside_the_panes():
    area = Rect(300, 20, 400, 200)
    items = lay_out_banner(
        area, "could not open " + "very-long-name-" * 3 + ".ply: " + "no vertex element " * 6, 200, 0, measure
    )
    assert len(items) > 2 and all(i.inside(area) for i in items)
    for a, b in itertools.combinations(items, 2):
        assert not a.overlaps(b)
