"""Difference and error images (gbviewer.outputs.differences): hand-built frames through the colour map, the robust
scale, the colour bar, and the references against renders made here."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.model.camera import camera_key
from gbviewer.outputs import differences, metrics
from gbviewer.outputs.differences import DIVERGING


def test_colour_map_at_minus_max_zero_plus_max_and_clipping_beyond():
    scale = 0.2
    ref = np.full((2, 4, 3), 0.5, np.float32)
    img = ref.copy()
    img[0, 0] -= 0.2  # -scale in every channel
    img[0, 1] += 0.2  # +scale
    img[0, 2] -= 0.45  # beyond -scale: clipped to the end colour
    img[0, 3] += [0.9, 0.9, 0.9]  # beyond +scale, and above 1 (clipped to 1 first: d = +0.5)
    img[1, 0] += [0.3, -0.3, 0.0]  # opposite signs in two channels cancel in the mean over RGB
    img[1, 1] += 0.1  # +scale / 2: half-way between the knots at +0.4 and +0.6
    img[1, 2] -= 0.03  # -0.15 scale: a quarter of the way from the knot at -0.2 to the one at 0
    d = differences.signed_difference(img, ref)
    assert d[0, 0] == pytest.approx(-0.2) and d[0, 3] == pytest.approx(0.5) and d[1, 0] == pytest.approx(0.0)
    rgb = differences.colour_difference(d, scale)
    assert rgb.shape == (2, 4, 3) and rgb.dtype == np.float32
    np.testing.assert_allclose(rgb[0, 0], DIVERGING[0], atol=1e-6)
    np.testing.assert_allclose(rgb[0, 1], DIVERGING[-1], atol=1e-6)
    np.testing.assert_array_equal(rgb[0, 2], DIVERGING[0])
    np.testing.assert_array_equal(rgb[0, 3], DIVERGING[-1])
    np.testing.assert_allclose(rgb[1, 0], DIVERGING[5], atol=1e-6)  # 0: the middle knot
    np.testing.assert_allclose(rgb[1, 1], (DIVERGING[7] + DIVERGING[8]) / 2, atol=1e-5)
    np.testing.assert_allclose(rgb[1, 2], 0.75 * DIVERGING[4] + 0.25 * DIVERGING[5], atol=1e-5)
    np.testing.assert_allclose(rgb[1, 3], DIVERGING[5], atol=1e-6)  # no difference
    # exact values of the table's ends and middle (Crameri's berlin): light blue, near black, light red
    np.testing.assert_allclose(
        differences.diverging(np.array([-1.0, 0.0, 1.0, -7.0, np.nan])),
        [
            [0.6211, 0.6902, 0.9995],
            [0.0983, 0.0470, 0.0347],
            [0.9999, 0.6801, 0.68],
            [0.6211, 0.6902, 0.9995],
            [0.0983, 0.0470, 0.0347],
        ],
        atol=1e-6,
    )
    with pytest.raises(ValueError, match="different sizes"):
        differences.signed_difference(img, ref[:1])


def test_colour_bar_runs_from_minus_to_plus_scale():
    bar = differences.colour_bar(21, 3)
    assert bar.shape == (3, 21, 3)
    np.testing.assert_allclose(bar[:, 0], np.broadcast_to(DIVERGING[0], (3, 3)), atol=1e-6)
    np.testing.assert_allclose(bar[1, 10], DIVERGING[5], atol=1e-6)
    np.testing.assert_allclose(bar[2, 20], DIVERGING[-1], atol=1e-6)
    # the bar is the map of evenly spaced values: colour_difference of a ramp gives the same pixels
    ramp = np.linspace(-0.3, 0.3, 21)[None]
    np.testing.assert_allclose(differences.colour_difference(ramp, 0.3)[0], bar[0], atol=1e-6)


def test_robust_scale_ignores_a_few_outliers_and_has_a_floor():
    d = np.full((100, 100), 0.02, np.float32)
    d[:5, :5] = 0.9  # 0.25 % of the pixels
    assert differences.robust_scale(d) == pytest.approx(0.02)
    assert differences.robust_scale(-d) == pytest.approx(0.02)
    assert differences.robust_scale(np.zeros((4, 4))) == differences.MIN_SCALE
    assert differences.robust_scale(np.full((2, 2), np.nan)) == differences.MIN_SCALE
    assert differences.format_scale(0.083123) == "0.0831"


def test_fidelity_is_metrics_psnr_and_ssim():
    rng = np.random.default_rng(3)
    a, b = rng.random((24, 32, 3)), rng.random((24, 32, 3))
    p, s = differences.fidelity(a, b)
    assert p == metrics.psnr(a, b) and s == metrics.ssim(a, b)


def test_dense_reference_is_the_scalar_8x8_render(bundled_scene, output_view):
    cam = output_view.at_sampling_rate(0.25)
    renderer = gb.get_renderer(bundled_scene)
    settings = gb.RenderSettings("gaussian_blending", background=(0.2, 0.3, 0.4))
    ref = differences.reference_image(renderer, cam, 0.25, "dense", settings)
    expected = gb.render(bundled_scene, cam, "scalar", supersample=8, background=(0.2, 0.3, 0.4)).rgb
    np.testing.assert_array_equal(ref, expected)


def test_box_reference_is_the_x1_render_box_downsampled(bundled_scene, output_view):
    renderer = gb.get_renderer(bundled_scene)
    cam = output_view.with_size(64, 48).at_sampling_rate(0.25)  # 16 x 12
    ref = differences.reference_image(renderer, cam, 0.25, "box")
    x1 = gb.render(bundled_scene, output_view.with_size(64, 48), "scalar").rgb
    assert ref.shape == (12, 16, 3)
    np.testing.assert_allclose(ref, metrics.box_downsample(x1, 4), atol=1e-6)
    np.testing.assert_array_equal(
        differences.reference_image(renderer, cam, 1.0, "box"), gb.render(bundled_scene, cam, "scalar").rgb
    )  # at x1: the scalar render itself
    assert differences.reference_image(renderer, cam, 2.0, "box") is None
    assert differences.reference_image(renderer, cam, 1 / 2.5, "box") is None
    assert differences.reference_note("box", 2.0) == "no box reference at x2 (only at 1/k): choose dense"
    assert differences.reference_note("box", 0.125) == ""
    assert differences.reference_note("dense", 2.0) == ""
    with pytest.raises(ValueError, match="expected one of box, dense"):
        differences.reference_settings("exact")


def test_camera_key_tells_cameras_apart(output_view):
    assert camera_key(output_view) == camera_key(output_view.at_sampling_rate(1.0))
    assert camera_key(output_view) != camera_key(output_view.at_sampling_rate(0.5))
    moved = gb.Camera(
        output_view.width,
        output_view.height,
        output_view.fx,
        output_view.fy,
        output_view.cx,
        output_view.cy,
        output_view.R,
        output_view.t + np.float32(0.01),
    )
    assert camera_key(moved) != camera_key(output_view)
    ortho = dataclasses.replace(output_view, projection="orthographic")
    assert camera_key(ortho) != camera_key(output_view)  # the same numbers, other pixels
