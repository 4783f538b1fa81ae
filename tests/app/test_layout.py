"""Pane rectangles, the loupe's texture window, the parts of a split pane."""

from __future__ import annotations

import pytest

from gbviewer.app.ui.layout import grid_shape, loupe_uv, pane_rects, split_parts


@pytest.mark.parametrize(
    "n,layout,shape",
    [
        (1, "row", (1, 1)),
        (2, "row", (1, 2)),
        (4, "row", (1, 4)),
        (2, "grid", (1, 2)),
        (3, "grid", (2, 2)),
        (4, "grid", (2, 2)),
    ],
)
def test_pane_rects_tile_the_viewport_without_overlap(n, layout, shape):
    assert grid_shape(n, layout) == shape
    rects = pane_rects(100, 30, 1001, 700, n, layout, gap=4)
    assert len(rects) == n
    for r in rects:
        assert 100 <= r.x and r.x + r.w <= 1101 and 30 <= r.y and r.y + r.h <= 730
    for a in range(n):
        for b in range(a + 1, n):
            ra, rb = rects[a], rects[b]
            assert ra.x + ra.w <= rb.x or rb.x + rb.w <= ra.x or ra.y + ra.h <= rb.y or rb.y + rb.h <= ra.y
    widths = {r.w for r in rects}
    assert max(widths) - min(widths) <= 1
    rows, cols = shape
    assert rects[cols - 1].x + rects[cols - 1].w == 1101  # last column reaches the right edge
    assert rects[-1].y + rects[-1].h == 730 or rows == 1 and rects[0].y + rects[0].h == 730


def test_loupe_uv_is_centred_sized_by_zoom_and_clamped():
    u0, v0, u1, v1 = loupe_uv(0.5, 0.5, 400, 200, radius_px=80, zoom=8)
    assert (u1 - u0) * 400 == pytest.approx(20) and (v1 - v0) * 200 == pytest.approx(20)
    assert (u0 + u1) / 2 == pytest.approx(0.5) and (v0 + v1) / 2 == pytest.approx(0.5)
    u0, v0, u1, v1 = loupe_uv(0.0, 1.0, 400, 200, 80, 8)
    assert u0 == pytest.approx(0) and v1 == pytest.approx(1)


def test_split_parts():
    assert split_parts(0.3) == ((0.0, 0.3), (0.3, 1.0))
    assert split_parts(-1) == ((0.0, 0.0), (0.0, 1.0))
