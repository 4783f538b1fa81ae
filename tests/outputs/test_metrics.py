"""Image quality measures (gbviewer.outputs.metrics) against hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gbviewer.outputs import metrics


def test_box_downsample_hand_case_and_ragged_edges():
    img = np.arange(5 * 7, dtype=np.float64).reshape(5, 7)  # 5x7 with k=2: the last row and column are cropped
    out = metrics.box_downsample(img, 2)
    assert out.shape == (2, 3)
    assert out[0, 0] == (0 + 1 + 7 + 8) / 4 and out[1, 2] == (18 + 19 + 25 + 26) / 4
    rgb = np.stack([img, 2 * img, 3 * img], axis=2)
    np.testing.assert_array_equal(metrics.box_downsample(rgb, 2)[..., 2], 3 * out)


def test_psnr_hand_cases():
    a = np.zeros((4, 4, 3))
    assert metrics.psnr(a, a + 0.1) == pytest.approx(20.0)  # mse 0.01
    assert metrics.psnr(a, a) == math.inf
    assert metrics.psnr(a - 5, a + 0.1) == pytest.approx(20.0)  # both clipped to [0, 1] first


def test_ssim_hand_cases():
    x = np.random.default_rng(0).uniform(size=(32, 32, 3))
    assert metrics.ssim(x, x) == pytest.approx(1.0)
    # constant images: SSIM = (2ab + C1) / (a^2 + b^2 + C1), C1 = (0.01)^2
    a, b, c1 = 0.5, 0.25, 1e-4
    assert metrics.ssim(np.full((16, 16, 3), a), np.full((16, 16, 3), b)) == pytest.approx(
        (2 * a * b + c1) / (a * a + b * b + c1), abs=1e-9
    )
    assert math.isnan(metrics.ssim(x[:10, :10], x[:10, :10]))  # the 11x11 window does not fit


def test_zoom_factor():
    assert [metrics.zoom_factor(r) for r in (1.0, 0.125, 0.5, 4.0, 1 / 3)] == [1, 8, 2, 4, 3]
    assert metrics.zoom_factor(1 / 3.7) is None and metrics.zoom_factor(2.5) is None


def test_reference_psnr_against_the_box_downsampled_x1():
    rng = np.random.default_rng(1)
    x1 = rng.uniform(size=(16, 24, 3))
    low = metrics.box_downsample(x1, 4) + 0.1
    assert metrics.reference_psnr(x1, low, 0.25) == pytest.approx(20.0)  # mse 0.01
    assert metrics.reference_psnr(x1, x1, 1.0) == math.inf
    assert metrics.reference_psnr(x1, low, 2.0) is None  # no reference above x1
    assert metrics.reference_psnr(x1, low, 1 / 3.7) is None  # not an integer factor
    assert metrics.reference_psnr(x1, low[:-1], 0.25) is None  # sizes that do not match


def test_flicker_measure():
    h, w = 8, 8
    smooth = [np.full((h, w, 3), 0.1 + 0.01 * t) for t in range(6)]  # constant-speed change: no second difference
    fl, pops = metrics.flicker(smooth)
    assert fl < 1e-9 and pops == 0
    popping = [f.copy() for f in smooth]
    for f in popping[3:]:
        f[2, 2] += 0.2  # one pixel jumps between frames 2 and 3
    fl, pops = metrics.flicker(popping)
    assert pops == pytest.approx(2 / (4 * h * w))  # seen at t = 2 and t = 3
    assert fl == pytest.approx(255 * 0.2 * 2 * 3 / (4 * h * w * 3))
