"""The stochastic mode (native/include/gbv/stochastic.h): a fixed seed and frame reproduce bit for bit, other frames
and seeds are other samples, the mean over frames is the float64 expectation (alpha blending in depth order,
tests/reference_stochastic.py) within its sampling error, `stochastic:N` converges to `scalar:N`, and every SIMD path
and the GLSL port make the same decisions but where float rounding puts alpha on the other side of the uniform."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest
from helpers import random_view
from reference import box_down
from reference_stochastic import expectation
from simd_helpers import VECTOR_PATHS, render

import gbviewer as gb
from gbviewer.render import CudaRenderer, Mode, RenderSettings
from gbviewer.render.presets import PRESETS

BACKGROUND = (0.2, 0.3, 0.4)
FRAMES = 256
SIGMAS = 6.0  # |mean - E| <= 6 sigma / sqrt(M) per pixel and channel: P(fail) < 2e-9 each, < 1e-4 per test
BIAS = 2e-6  # P(u < alpha) is alpha rounded up to the 2^-24 grid, plus float32 alpha and colour rounding


def _scene(seed=2):
    return random_view(seed, sh_degree=1, W=40, H=32, max_px_sigma=3.0)


def _mean(scene, cam, supersample, frames=FRAMES, seed=0, mode="stochastic", background=BACKGROUND):
    frames_rgb = [
        gb.render(scene, cam, mode=mode, supersample=supersample, background=background, seed=seed, frame=f).rgb.astype(
            np.float64
        )
        for f in range(frames)
    ]
    return np.mean(frames_rgb, axis=0)


def test_seed_and_frame_reproduce_bit_for_bit_and_vary():
    scene, cam = _scene()
    a = gb.render(scene, cam, mode="stochastic", seed=7, frame=3)
    b = gb.render(scene, cam, mode="stochastic", seed=7, frame=3)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)
    assert set(np.unique(a.alpha)) <= {0.0, 1.0}  # kept fragments are opaque: a sample is covered or not
    for other in ({"seed": 7, "frame": 4}, {"seed": 8, "frame": 3}):
        c = gb.render(scene, cam, mode="stochastic", **other)
        assert (np.abs(c.rgb - a.rgb).max(axis=2) > 0).mean() > 0.05, other


@pytest.mark.parametrize("mode", ["stochastic", "stochastic_popfree"])
def test_mean_over_frames_is_depth_ordered_alpha_blending(mode):
    """Per pixel, the mean of M frames is E (reference_stochastic.expectation: centre-depth order, or per pixel the
    depth planes' order) within 6 sigma / sqrt(M), sigma the sample's standard deviation computed from the same
    reference; and it is no closer to E by chance: the normalised errors have about unit variance."""
    scene, cam = _scene()
    mean = _mean(scene, cam, 1, mode=mode)
    E, var = expectation(scene, cam, 1, BACKGROUND, popfree=mode == "stochastic_popfree")
    err = np.abs(mean - E)
    bound = SIGMAS * np.sqrt(var / FRAMES) + BIAS
    assert (err <= bound).all(), f"max excess {(err - bound).max():.3g}"
    z = (mean - E)[var > 1e-4] / np.sqrt(var[var > 1e-4] / FRAMES)
    assert z.size > 500 and 0.7 < z.std() < 1.3, z.std()


def test_supersampled_converges_to_scalar_n():
    """stochastic:2 is four independent samples per pixel: its mean is the box average of the samples' expectations
    (scalar:2's alpha blending, without the early stop), within the box mean's sampling error; and the float32
    scalar:2 render lies within its early stop (T < 1e-4) of that expectation."""
    scene, cam = _scene(5)
    n = 2
    mean = _mean(scene, cam, n, frames=128)
    E, var = expectation(scene, cam, n, BACKGROUND)
    E_out, var_out = box_down(E, n), box_down(var, n) / (n * n)
    assert (np.abs(mean - E_out) <= SIGMAS * np.sqrt(var_out / 128) + BIAS).all()
    scalar = gb.render(scene, cam, mode="scalar", supersample=n, background=BACKGROUND).rgb
    assert np.abs(scalar - E_out).max() < 2e-3


@pytest.mark.parametrize("mode", ["stochastic", "stochastic_popfree"])
@pytest.mark.parametrize("path", VECTOR_PATHS)
def test_vector_paths_make_the_scalar_paths_decisions(path, mode):
    """The decisions are the same integer hash on every path; only alpha's exp differs in its last bits, so a pixel
    may differ only where some fragment's uniform lies within float rounding of its alpha: a handful of pixels."""
    scene, cam = _scene()
    for supersample in (1, 2):
        for frame in range(4):
            kw = dict(background=BACKGROUND, frame=frame)
            ref = render("scalar", scene, cam, mode, supersample, **kw)
            vec = render(path, scene, cam, mode, supersample, **kw)
            assert vec.stats.simd == path and ref.stats.simd == "scalar"
            differ = np.abs(vec.rgb - ref.rgb).max(axis=2) > 1e-5
            assert differ.sum() <= 2 + 2e-3 * differ.size, (supersample, frame, differ.sum())


def test_trace_names_discarded_fragments():
    scene, cam = _scene()
    frame = gb.render(scene, cam, mode="stochastic")
    y, x = np.unravel_index(np.argmax(frame.alpha > 0), frame.alpha.shape)
    trace = gb.get_renderer(scene, "cpu").trace(cam, RenderSettings(Mode.STOCHASTIC), int(x), int(y))
    rejected = [step.rejected for sample in trace.samples for step in sample.steps]
    assert "" in rejected  # the kept fragment
    assert all(
        r in ("", "discarded", "outside_box", "invalid_exponent", "below_cutoff", "alpha_below_min", "terminated")
        for r in rejected
    )


def test_settings_and_spec():
    s = RenderSettings.parse("stochastic:3", seed=5, frame=9)
    assert (s.mode, s.supersample, s.seed, s.frame, s.spec) == (Mode.STOCHASTIC, 3, 5, 9, "stochastic:3")
    with pytest.raises(gb.RenderError, match="seed"):
        RenderSettings(Mode.STOCHASTIC, seed=-1)
    with pytest.raises(gb.RenderError, match="frame"):
        RenderSettings(Mode.STOCHASTIC, frame=2**32)


@pytest.mark.parametrize("mode", ["scalar", "stopthepop", "eval3d", "gaussian_blending"])
def test_seed_and_frame_are_refused_where_they_change_nothing(mode):
    """Like stopthepop's queue: a seed or frame index on a mode without keep decisions is one line, not ignored."""
    scene, cam = _scene()
    for key in ("seed", "frame"):
        with pytest.raises(gb.RenderError, match=f"{key} 3 applies to the stochastic modes .*not {mode}"):
            gb.render(scene, cam, mode=mode, **{key: 3})
    assert RenderSettings.parse(mode, seed=0, frame=0) == RenderSettings.parse(mode)
    assert RenderSettings.parse("preset:spark-stochastic", frame=3).frame == 3


@pytest.mark.parametrize("name", ["spark-stochastic", "supersplat-stochastic"])
def test_stochastic_presets_are_the_expectation_with_their_filter(name):
    """A stochastic preset keeps fragments with its viewer's filtered alpha: its mean over frames is the expectation
    computed with that filter, and not the one without it (the filter changes alphas, or culls splats, by far more
    than the sampling error)."""
    scene, cam = _scene()
    mean = _mean(scene, cam, 1, mode=f"preset:{name}")
    E, var = expectation(scene, cam, 1, BACKGROUND, asdict(PRESETS[name].view_filter))
    assert (np.abs(mean - E) <= SIGMAS * np.sqrt(var / FRAMES) + BIAS).all()
    E_plain, _ = expectation(scene, cam, 1, BACKGROUND)
    assert (np.abs(mean - E_plain) > SIGMAS * np.sqrt(var / FRAMES) + BIAS).any()


def _same_decisions(backend: str, mode: str) -> None:
    """Frames of `backend` are the CPU's but where float rounding puts a fragment's alpha on the other side of its
    uniform: the same (seed, frame, sample, splat index) hash on every backend."""
    scene, cam = _scene()
    for supersample in (1, 2):
        for frame in range(3):
            kw = dict(mode=mode, supersample=supersample, background=BACKGROUND, seed=3, frame=frame)
            cpu = gb.render(scene, cam, **kw)
            other = gb.render(scene, cam, backend=backend, **kw)
            assert other.stats.backend == backend
            differ = np.abs(other.rgb - cpu.rgb).max(axis=2) > 1e-5
            assert differ.sum() <= 2 + 2e-3 * differ.size, (supersample, frame, differ.sum())


@pytest.mark.parametrize("mode", ["stochastic", "stochastic_popfree"])
def test_glsl_makes_the_cpus_decisions(gl, mode):
    _same_decisions("glsl", mode)


@pytest.mark.parametrize("mode", ["stochastic", "stochastic_popfree"])
def test_cuda_makes_the_cpus_decisions(mode):
    ok, why = CudaRenderer.available()
    if not ok:
        pytest.skip(f"no CUDA runtime here: {why}")
    _same_decisions("cuda", mode)


def _parallel_disks(yaw_deg: float):
    """A red disk at z = 5 (centre x = -0.5) in front of a blue one at z = 5.2 (centre x = +0.5), both facing the
    camera, opacity 0.9; the camera at the origin turned by `yaw_deg` about y. Beyond about 11 degrees the blue
    disk's centre is the nearer one, while along every ray the red disk stays in front."""
    c0 = 0.28209479177387814
    sh = np.array([[[0.5 / c0, -0.5 / c0, -0.5 / c0]], [[-0.5 / c0, -0.5 / c0, 0.5 / c0]]])
    scene = gb.Scene.from_arrays(
        np.array([[-0.5, 0.0, 5.0], [0.5, 0.0, 5.2]]),
        np.array([[1.0, 1.0, 1e-4]] * 2),
        np.array([[1.0, 0.0, 0.0, 0.0]] * 2),
        np.array([0.9, 0.9]),
        sh,
    )
    a = np.radians(yaw_deg)
    R = np.array([[np.cos(a), 0.0, -np.sin(a)], [0.0, 1.0, 0.0], [np.sin(a), 0.0, np.cos(a)]])
    return scene, gb.Camera(32, 24, 30.0, 30.0, 16.0, 12.0, R, np.zeros(3))


def test_popfree_keeps_the_per_ray_order_when_centre_depths_swap():
    """Unturned, both modes have one order (red in front) and one expectation. Turned so that the blue disk's centre
    is nearer, stochastic puts blue in front where the disks overlap (its depth test uses centre depths) and
    stochastic_popfree still red (each disk's plane along the ray); each mode's mean over frames is its expectation."""
    for yaw in (0.0, -15.0):
        scene, cam = _parallel_disks(yaw)
        view_z = scene.means @ cam.R.T + cam.t
        assert (view_z[1, 2] < view_z[0, 2]) == (yaw != 0.0)
        E = {}
        for mode in ("stochastic", "stochastic_popfree"):
            mean = _mean(scene, cam, 1, frames=64, mode=mode, background=(0.0, 0.0, 0.0))
            E[mode], var = expectation(scene, cam, 1, popfree=mode == "stochastic_popfree")
            assert (np.abs(mean - E[mode]) <= SIGMAS * np.sqrt(var / 64) + BIAS).all(), (yaw, mode)
        st, pf = E["stochastic"], E["stochastic_popfree"]
        if yaw == 0.0:
            np.testing.assert_allclose(st, pf, atol=1e-12)
            continue
        # red in front: red shows its full alpha a_r and blue a_b (1 - a_r); blue in front the other way round
        assert (pf[..., 0] >= st[..., 0] - 1e-12).all() and (st[..., 2] >= pf[..., 2] - 1e-12).all()
        assert ((pf[..., 0] - st[..., 0]) > 0.2).sum() > 10 and ((st[..., 2] - pf[..., 2]) > 0.2).sum() > 10
