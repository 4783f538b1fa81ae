"""Sampling-rate steps, the slider, labels, render sizes, the resolution drop while moving."""

from __future__ import annotations

import pytest

import gbviewer as gb
from gbviewer.app.frames import rates


def test_rate_steps_walk_every_step_both_ways():
    r, seen = 1 / 8, [1 / 8]
    for _ in range(10):
        r = rates.step_rate(r, +1)
        seen.append(r)
    assert seen[:7] == [1 / 8, 1 / 4, 1 / 2, 1, 2, 4, 8] and seen[-1] == 8
    r, down = 8.0, []
    for _ in range(8):
        r = rates.step_rate(r, -1)
        down.append(r)
    assert down[:6] == [4, 2, 1, 1 / 2, 1 / 4, 1 / 8] and down[-1] == 1 / 8


def test_rate_step_from_a_continuous_value_goes_to_the_neighbour_step():
    assert rates.step_rate(0.3, +1) == 0.5 and rates.step_rate(0.3, -1) == 0.25
    assert rates.step_rate(3.0, +1) == 4 and rates.step_rate(3.0, -1) == 2


def test_rate_slider_is_log2_snaps_to_steps_and_clamps():
    for r in rates.RATE_STEPS:
        assert rates.slider_to_rate(rates.rate_to_slider(r)) == pytest.approx(r)
    assert rates.slider_to_rate(-3.02) == 1 / 8  # snapped
    assert rates.slider_to_rate(0.5) == pytest.approx(2**0.5)  # continuous in between
    assert rates.slider_to_rate(9) == 8 and rates.slider_to_rate(-9) == 1 / 8
    assert rates.clamp_rate(float("nan")) == 1.0 and rates.clamp_rate(100) == 8


def test_render_size_matches_camera_at_sampling_rate():
    cam = gb.Camera.look_at([0, 0, -3], [0, 0, 0], width=523, height=401)
    for r in (8, 1, 0.3, 1 / 8, 1 / 1000):
        c = cam.at_sampling_rate(r)
        assert rates.render_size(523, 401, r) == (c.width, c.height)


def test_preview_factor_only_while_moving_and_only_as_much_as_needed():
    assert rates.preview_factor(640 * 480, 1e-3, 60, moving=False) == 1.0
    assert rates.preview_factor(640 * 480, None, 60, moving=True) == 1.0
    assert rates.preview_factor(100 * 100, 1e-3, 60, moving=True) == 1.0  # 10 ms fits
    assert rates.preview_factor(640 * 480, 1e-3, 60, moving=True) == 0.25  # 307 ms -> 77 at 1/2, 19 at 1/4
    assert rates.preview_factor(4000 * 4000, 1e-3, 1, moving=True) == 0.125  # never below 1/8
