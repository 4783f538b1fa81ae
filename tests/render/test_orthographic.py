"""Orthographic cameras (`Camera(projection="orthographic")`, fx and fy in pixels per world unit) on the CPU backend:
every mode against the float64 reference with the tolerances of test_render_reference.py and test_oit.py, the
preprocessed splat against J W Sigma W^T J^T (J = diag(fx, fy)) in float64, the SH view direction, and the
perspective limit. The GLSL and CUDA backends are held to the CPU in test_glsl.py and test_cuda.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import front_camera, random_scene, random_view
from reference import MODES, reference_render_oit
from reference_preprocess import quat_to_rotmat
from simd_helpers import preprocessed
from test_oit import check, oit, oit_of, with_view_weights
from test_render_reference import BACKGROUND, SCENES, _check_strict

import gbviewer as gb
from gbviewer.model.cells import cells_for


def f32(bits: np.ndarray) -> np.ndarray:
    """Float32 values of captured Splat2D fields (stored as their bits)."""
    return bits.view(np.float32).astype(np.float64)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed,sh_degree,filter3d", SCENES)
def test_matches_reference(mode, supersample, seed, sh_degree, filter3d):
    """scalar, mip, analytic, gaussian_blending: every kind of splat (behind, at the near plane, off screen, huge,
    degenerate) within 1e-4 of the float64 reference, threshold ties excepted."""
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d, projection="orthographic")
    frame = gb.render(scene, cam, mode=mode, supersample=supersample, background=BACKGROUND)
    _, _, alpha = _check_strict(frame, scene, cam, mode, supersample)
    assert (alpha > 0.05).mean() > 0.5, "scene should cover most of the image"


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("mode", ["wsr", "duplex"])
def test_order_independent_modes_match_reference(mode, supersample):
    """wsr (view weights along the forward axis, depth correction on Z) and duplex (cells projected
    orthographically)."""
    scene, cam = random_view(51, n=140, sh_degree=3, projection="orthographic")
    scene = with_view_weights(scene, 51, sigma=4.0)
    if mode == "wsr":
        frame = gb.render(scene, cam, "wsr", supersample, background=BACKGROUND, depth_correct=True)
        params = oit("wsr", wbg=oit_of(scene).weight_background, sigma=4.0, depth_correct=True)
        check(frame, reference_render_oit(scene, cam, "wsr", params, None, supersample, BACKGROUND))
    else:
        frame = gb.render(scene, cam, "duplex", supersample, background=BACKGROUND, et_grade=2.5, cell_size=5)
        params = oit("duplex", 2.5, wbg=oit_of(scene).weight_background)
        check(frame, reference_render_oit(scene, cam, "duplex", params, cells_for(scene, 5), supersample, BACKGROUND))
        assert 0 < frame.stats.cells_visible <= frame.stats.cells


def test_splat_is_the_linear_projection():
    """Each preprocessed splat (gaussian_blending: no dilation) has screen position (fx X + cx, fy Y + cy), depth Z
    and conic the inverse of J W Sigma W^T J^T with J = diag(fx, fy), computed here in float64; those with Z at or
    behind the near plane are culled."""
    scene, cam = random_view(14, n=300, sh_degree=0, projection="orthographic")
    rec, _ = preprocessed("scalar", scene, cam, "gaussian_blending")
    R, t = cam.R.astype(np.float32).astype(np.float64), cam.t.astype(np.float32).astype(np.float64)
    view = scene.means.astype(np.float64) @ R.T + t
    M = quat_to_rotmat(scene.quats) * scene.scales.astype(np.float64)[:, None, :]
    J = np.array([[np.float32(cam.fx), 0, 0], [0, np.float32(cam.fy), 0]], np.float64)
    cov = J @ R @ (M @ M.transpose(0, 2, 1)) @ R.T @ J.T
    valid = rec["valid"] == 1
    assert not valid[view[:, 2] <= cam.near].any(), "a splat at or behind the near plane was kept"
    # splats wider than 0.3 px: their conic is well conditioned in float32
    sigma2 = np.linalg.eigvalsh(cov)[:, 0]
    ok = valid & (sigma2 > 0.09)
    assert ok.sum() > 100, ok.sum()
    s = rec["splat"][ok]
    np.testing.assert_allclose(
        f32(s["xy"]), np.c_[cam.fx * view[ok, 0] + cam.cx, cam.fy * view[ok, 1] + cam.cy], rtol=0, atol=1e-3
    )
    np.testing.assert_allclose(f32(s["depth"]), view[ok, 2], rtol=1e-6)
    inv = np.linalg.inv(cov[ok])
    want = np.c_[inv[:, 0, 0], inv[:, 0, 1], inv[:, 1, 1]]  # the conic (a, b, c) is the inverse covariance
    err = np.abs(f32(s["conic"]) - want).max(axis=1) / np.abs(want).max(axis=1)
    assert err.max() < 1e-4, f"conic off by {err.max():.2e} (relative) at splat {np.flatnonzero(ok)[err.argmax()]}"
    # the perspective Jacobian of the same pose gives other ellipses: the check above can fail
    persp, _ = preprocessed("scalar", scene, cam.with_projection("perspective", 3.0), "gaussian_blending")
    both = ok & (persp["valid"] == 1)
    assert not np.allclose(f32(persp["splat"]["conic"][both]), f32(rec["splat"]["conic"][both]), rtol=0.01)


def test_every_splat_is_seen_along_the_forward_axis():
    """Splats with the same SH coefficients get the same colour wherever they are in an orthographic view (parallel
    rays), the colour of a perspective camera's splat straight ahead; in a perspective view they differ."""
    n = 50
    rng = np.random.default_rng(3)
    means = np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 6, n)]
    means[0] = [0.0, 0.0, 4.0]  # on the optical axis
    sh = np.tile(rng.normal(0, 0.5, (1, 16, 3)), (n, 1, 1))
    scene = gb.Scene.from_arrays(means, np.full((n, 3), 0.05), np.tile([1.0, 0, 0, 0], (n, 1)), np.full(n, 0.8), sh)
    cam = front_camera(64, 48).with_projection("orthographic", 4.0)
    ortho, _ = preprocessed("scalar", scene, cam, "scalar")
    persp, _ = preprocessed("scalar", scene, front_camera(64, 48), "scalar")
    assert (ortho["valid"] == 1).sum() > 20 and ortho["valid"][0] == 1 and persp["valid"][0] == 1
    colours = f32(ortho["splat"]["color"][ortho["valid"] == 1])
    np.testing.assert_array_equal(colours, np.broadcast_to(f32(persp["splat"]["color"][0]), colours.shape))
    assert np.ptp(f32(persp["splat"]["color"][persp["valid"] == 1]), axis=0).max() > 0.01


@pytest.mark.parametrize("mode", MODES + ("wsr", "duplex"))
def test_far_perspective_camera_converges_to_orthographic(mode):
    """A perspective camera backed away by D along its axis, its focal length fx D (the orthographic scale at the
    scene), renders ever closer to the orthographic image as D grows: its rays become parallel. The mean difference
    falls as 1/D (measured: 0.1, 0.02, 2e-3, 2e-4 for D = 10 .. 10^4 in every mode; beyond, float32 depths of
    D + z limit it)."""
    scene = random_scene(300, seed=8, sh_degree=3)
    ortho = front_camera(64, 48).with_projection("orthographic", 4.0)
    ref = gb.render(scene, ortho, mode).rgb
    errors = []
    for D in (10.0, 100.0, 1000.0, 10000.0):
        far = replace(ortho, t=ortho.t + [0, 0, D], near=ortho.near + D).with_projection("perspective", D)
        errors.append(float(np.abs(gb.render(scene, far, mode).rgb - ref).mean()))
    assert all(b < 0.25 * a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 5e-4, errors
