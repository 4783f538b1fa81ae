"""Camera paths of zoom videos (gbviewer.model.camera_paths): zoom, dolly and rate sweeps scale the content as
stated."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import OUTPUT_W as W

import gbviewer as gb
from gbviewer.model import camera_paths


def test_zoom_and_dolly_scale_the_content(bundled_scene, output_view):
    z = camera_paths.zoom_path(output_view, 5, 1.0, 1.0 / 8.0)
    assert [pf.rate for pf in z] == pytest.approx([8 ** (-i / 4) for i in range(5)], rel=1e-12)
    assert z[0].camera.fx == output_view.fx and np.array_equal(z[0].camera.t, output_view.t)
    assert math.isclose(z[-1].camera.fx, output_view.fx / 8) and z[-1].camera.width == W
    depth = camera_paths.scene_focus_depth(bundled_scene, output_view)
    d = camera_paths.dolly_path(output_view, 3, 1.0, 1.0 / 4.0, depth)
    p_cam = np.array([0.3, -0.2, depth])  # a point at the focus depth, in output_view camera coordinates
    p_world = output_view.R.T @ (p_cam - output_view.t)
    for pf in d:
        q = pf.camera.R @ p_world + pf.camera.t
        u = pf.camera.fx * q[0] / q[2] + pf.camera.cx
        assert math.isclose(u - output_view.cx, pf.rate * output_view.fx * p_cam[0] / depth, rel_tol=1e-9)
    cx, cy = output_view.cx, output_view.cy
    assert z[-1].map_box((cx - 8, cy, 16, 8)) == pytest.approx((cx - 1, cy, 2, 1))
    r = camera_paths.rate_path(output_view, 2, 1.0, 0.25)
    assert (r[-1].camera.width, r[-1].camera.height, r[-1].width) == (24, 16, W)


def test_orthographic_zoom_scales_the_pixels_per_unit(bundled_scene, output_view):
    """An orthographic zoom scales fx, fy (pixels per world unit): a point's offset from the principal point scales
    with the rate whatever its depth; a dolly, which would change nothing, is refused."""
    ortho = output_view.with_projection("orthographic", 3.0)
    z = camera_paths.zoom_path(ortho, 3, 1.0, 1.0 / 4.0)
    for p_cam in ([0.3, -0.2, 1.0], [0.3, -0.2, 7.0]):
        p_world = ortho.R.T @ (np.array(p_cam) - ortho.t)
        for pf in z:
            q = pf.camera.R @ p_world + pf.camera.t
            assert pf.camera.orthographic
            assert math.isclose(pf.camera.fx * q[0], pf.rate * ortho.fx * p_cam[0], rel_tol=1e-9)
    with pytest.raises(gb.GBViewerError, match="orthographic.*--path zoom"):
        camera_paths.camera_path("dolly", ortho, 3, scene=bundled_scene)
    r = camera_paths.rate_path(ortho, 2, 1.0, 0.25)
    assert r[-1].camera.orthographic and math.isclose(r[-1].camera.fx, ortho.fx / 4)
