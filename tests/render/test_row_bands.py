"""Row bands (native/cpu/blend_bands.h): a lane group walks only the tile-list entries whose pixel box meets its row's
band, until a gaussian_blending window leaves the band and the group walks the rest of the whole list (fast
gaussian_blending on a vector path: one band per block of rows, its lane groups' rows). Exact: the same pixels, alpha,
evaluation counts and final windows as every group walking the whole list, on every SIMD path."""

from __future__ import annotations

import numpy as np
import pytest
from simd_helpers import ALL_PATHS, MODES, _needle_scene, _small_opaque_scene, render

import gbviewer as gb
from gbviewer import _native


def _zoomed_out_scene(seed):
    """Thousands of splats of a pixel or less over a 64 x 48 image: most tiles' lists are long and every entry meets
    a few rows (the case the bands are for)."""
    rng = np.random.default_rng(seed)
    n = 6000
    z = rng.uniform(4, 8, n)
    means = np.c_[rng.uniform(-0.6, 0.6, n) * z, rng.uniform(-0.45, 0.45, n) * z, z]
    scales = np.exp(rng.uniform(np.log(0.005), np.log(0.08), (n, 3)))
    op = rng.uniform(0.05, 1.0, n)
    cam = gb.Camera(64, 48, 50.0, 50.0, 32.0, 24.0, np.eye(3), np.zeros(3))
    return gb.Scene.from_arrays(means, scales, rng.normal(size=(n, 4)), op, rng.uniform(-1, 1, (n, 1, 3))), cam


def _debug(mode):
    return "window" if mode.startswith("gaussian_blending") else "none"  # evaluation counts: always


def _whole_lists(path, scene, cam, mode, supersample):
    _native.testing.set_row_bands(False)
    try:
        return render(path, scene, cam, mode, supersample=supersample, debug=_debug(mode))
    finally:
        _native.testing.set_row_bands(True)


@pytest.mark.parametrize("path", ALL_PATHS)
@pytest.mark.parametrize("mode", MODES + ("gaussian_blending+fast",))
@pytest.mark.parametrize("make_scene", [_zoomed_out_scene, _small_opaque_scene, _needle_scene])
def test_row_bands_change_no_pixel(path, mode, make_scene):
    scene, cam = make_scene(7)
    # gaussian_blending: the default band; one just wider than the group box's start, which windows leave as they
    # move (the walk then goes on over the whole list from there); one narrower, left before the first entry
    margins = (2.0, 1.02, 0.5) if mode.startswith("gaussian_blending") else (2.0,)
    for c in (cam, cam.at_sampling_rate(1 / 2), cam.at_sampling_rate(1 / 4)):
        for supersample in (1, 2):
            ref = _whole_lists(path, scene, c, mode, supersample)
            for margin in margins:
                _native.testing.set_gaussian_band_margin(margin)
                try:
                    got = render(path, scene, c, mode, supersample=supersample, debug=_debug(mode))
                finally:
                    _native.testing.set_gaussian_band_margin(2.0)
                np.testing.assert_array_equal(got.rgb, ref.rgb)
                np.testing.assert_array_equal(got.alpha, ref.alpha)
                assert set(got.debug) == set(ref.debug) >= {"evals"}
                for key in ref.debug:
                    np.testing.assert_array_equal(got.debug[key], ref.debug[key], err_msg=key)
