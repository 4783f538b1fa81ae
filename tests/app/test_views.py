"""Debug views and the 16-bit PNG of a pane."""

from __future__ import annotations

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.app.frames import views


def test_debug_views():
    rgb = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    alpha = np.linspace(0, 1, 20, dtype=np.float32).reshape(4, 5)
    frame = gb.Frame(rgb, alpha, {}, {"evals": np.arange(20).reshape(4, 5)})
    img, legend = views.visualize(frame, "alpha")
    assert img[..., 0] == pytest.approx(alpha) and legend
    img, _ = views.visualize(frame, "transmittance")
    assert img[..., 1] == pytest.approx(1 - alpha)
    img, legend = views.visualize(frame, "evals")
    assert img.shape == (4, 5, 3) and "19" in legend
    img, legend = views.visualize(frame, "window")  # no window plane: colour, saying why
    assert img is rgb and "gaussian_blending" in legend
    frame.debug["window"] = np.full((4, 5, 2), 2.0, np.float32)
    img, legend = views.visualize(frame, "window")
    assert img.shape == (4, 5, 3) and "2.00" in legend
    assert views.visualize(frame, "color")[0] is rgb


def test_png16_round_trip_keeps_full_precision():
    rgb = np.random.default_rng(1).random((7, 9, 3)).astype(np.float32)
    data = views.encode_png16(rgb)
    back = views.decode_png16(data)
    assert back.shape == (7, 9, 3) and back.dtype == np.uint16
    assert np.abs(back / 65535 - rgb).max() < 1e-5
    from io import BytesIO

    from PIL import Image

    im = Image.open(BytesIO(data))  # a valid PNG for other readers too
    assert im.size == (9, 7)
