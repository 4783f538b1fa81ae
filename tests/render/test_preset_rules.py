"""The viewer presets' rules beyond the 2D filter (gbviewer/render/view_filter.py: dc_clamp, support, sort_radial),
each on a scene built so that the rule changes the image: hand-worked values, the float64 reference re-implementing
the rule (reference_preprocess / reference_blend), and the rule off reproducing the scalar mode; on the CPU (scalar
and vector paths: the default path) and the GLSL port."""

from __future__ import annotations

import math
from dataclasses import asdict, replace

import numpy as np
import pytest
from reference import reference_render

import gbviewer as gb
from gbviewer.model.scene import SH_C0
from gbviewer.render import RenderSettings
from gbviewer.render.presets import PRESETS, QUAD_SIGMAS
from gbviewer.render.view_filter import ViewFilter

SH_C1 = 0.4886025119029199
TOL = 1e-4  # as test_presets.py


def render(scene: gb.Scene, cam: gb.Camera, vf: ViewFilter, backend: str = "cpu", sh_degree: int = 3) -> gb.Frame:
    return gb.get_renderer(scene, backend).render(cam, RenderSettings(view_filter=vf, sh_degree=sh_degree))


def camera(W: int = 32, H: int = 32, f: float = 100.0) -> gb.Camera:
    return gb.Camera(W, H, f, f, W / 2 + 0.5, H / 2 + 0.5, np.eye(3), np.zeros(3))


def splats(means, sigmas, opacities, base, rest=0.0) -> gb.Scene:
    """Isotropic splats of world sigma `sigmas`, base colour `base` (0.5 + C0 dc per channel), SH degree 1 with every
    rest coefficient `rest`."""
    n = len(means)
    sh = np.zeros((n, 4, 3))
    sh[:, 0] = (np.asarray(base, float).reshape(n, 3) - 0.5) / SH_C0
    sh[:, 1:] = rest
    s = np.repeat(np.asarray(sigmas, float).reshape(n, 1), 3, 1)
    return gb.Scene.from_arrays(means, s, np.tile([1.0, 0, 0, 0], (n, 1)), opacities, sh)


def check_reference(scene, cam, vf: ViewFilter, backend: str = "cpu") -> gb.Frame:
    frame = render(scene, cam, vf, backend)
    rgb, alpha, ties = reference_render(scene, cam, "scalar", return_ties=True, view_filter=asdict(vf))
    err = np.maximum(np.abs(frame.rgb - rgb).max(-1), np.abs(frame.alpha - alpha))
    assert np.where(ties, 0.0, err).max() <= TOL and ties.sum() <= 4
    return frame


def test_base_colour_above_one_is_clamped_before_the_sh_bands():
    """A base colour of 1.3 with a negative z band (the splat on the axis: direction (0, 0, 1), so only coefficient 2
    adds SH_C1 * rest): spark shows 1 - 0.195, the scalar mode 1.3 - 0.195; a base below 0 clamps to 0 likewise."""
    scene = splats([[0.0, 0.0, 5.0]], [0.05], [0.5], [[1.3, -0.2, 0.6]], rest=-0.4)
    cam = camera()
    band = SH_C1 * -0.4
    spark = check_reference(scene, cam, PRESETS["spark"].view_filter)
    plain = check_reference(scene, cam, ViewFilter(0.3, compensate=True))
    a = spark.alpha[16, 16]
    np.testing.assert_allclose(spark.rgb[16, 16], np.maximum(0, np.array([1.0, 0.0, 0.6]) + band) * a, atol=2e-6)
    np.testing.assert_allclose(plain.rgb[16, 16], np.maximum(0, np.array([1.3, -0.2, 0.6]) + band) * a, atol=2e-6)
    assert plain.alpha[16, 16] == a


def test_dc_clamp_alone_reproduces_the_scalar_mode_inside_zero_one():
    """The clamp changes nothing where every base colour lies in [0, 1]: bit for bit."""
    rng = np.random.default_rng(5)
    scene = splats(
        rng.uniform(-1, 1, (60, 3)) + [0, 0, 6],
        rng.uniform(0.05, 0.3, 60),
        rng.uniform(0.2, 0.9, 60),
        rng.uniform(0.0, 1.0, (60, 3)),
        rest=0.1,
    )
    cam = camera(48, 40, 40.0)
    a, b = render(scene, cam, ViewFilter(dc_clamp=True)), render(scene, cam, ViewFilter())
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)


def test_support_cuts_alpha_beyond_the_quad():
    """antimatter15 (no dilation): an opaque splat of projected variance 1 px^2 gives exp(-d^2 / 2) at a pixel d px
    from its centre up to d^2 = 8, then nothing, where the scalar mode's 1/255 cut-off still keeps d^2 = 8.41."""
    f, z = 100.0, 5.0
    cam = camera(32, 32, f)
    scene = splats([[0.0, 0.0, z]], [z / f], [0.98], [[0.5, 0.5, 0.5]])
    vf = PRESETS["antimatter15"].view_filter
    cut = check_reference(scene, cam, vf)
    full = check_reference(scene, cam, replace(vf, support=0.0))
    # pixel (16 + k, 16): d = k px; rows beyond sqrt(8) = 2.83 are cut
    for k, d2 in ((2, 4.0), (3, 9.0)):
        assert full.alpha[16, 16 + k] == pytest.approx(0.98 * math.exp(-d2 / 2), abs=2e-6)
    assert cut.alpha[16, 18] == full.alpha[16, 18] and cut.alpha[16, 19] == 0.0
    assert cut.alpha[17, 19] == 0.0 < full.alpha[17, 19]  # d^2 = 10
    assert cut.alpha.sum() < full.alpha.sum()


def radial_pair() -> tuple[gb.Scene, gb.Camera]:
    """Two large splats: red off-axis at (1.2, 0, 5) (distance 5.14), blue on the axis at (0, 0, 5.1) (distance 5.1).
    By view-space z red comes first, by distance from the eye blue; both cover the middle of the image."""
    scene = splats([[1.2, 0.0, 5.0], [0.0, 0.0, 5.1]], [0.8, 0.8], [0.7, 0.7], [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    return scene, camera(32, 32, 30.0)


def test_radial_sort_orders_by_distance_from_the_eye():
    scene, cam = radial_pair()
    z = check_reference(scene, cam, ViewFilter())
    radial = check_reference(scene, cam, ViewFilter(sort_radial=True))
    # the centre pixel: red in front by z (more red, less blue), blue in front by distance
    assert z.rgb[16, 16, 0] > radial.rgb[16, 16, 0] + 0.05
    assert radial.rgb[16, 16, 2] > z.rgb[16, 16, 2] + 0.05
    assert np.array_equal(radial.alpha, z.alpha)  # the order changes the colour, not the coverage


def test_radial_sort_is_view_z_for_an_orthographic_camera():
    scene, cam = radial_pair()
    ortho = gb.Camera(32, 32, 6.0, 6.0, 16.5, 16.5, np.eye(3), np.zeros(3), projection="orthographic")
    a, b = render(scene, ortho, ViewFilter(sort_radial=True)), render(scene, ortho, ViewFilter())
    assert np.array_equal(a.rgb, b.rgb)


def test_switching_rules_rebuilds_the_stage():
    """The rules that change the per-camera stage (colour, depth) are part of its key: one renderer, one camera,
    the rule on, off and on again renders each as a fresh renderer does."""
    scene, cam = radial_pair()
    r = gb.get_renderer(scene, "cpu")
    on = RenderSettings(view_filter=ViewFilter(sort_radial=True, dc_clamp=True))
    first, off, again = (r.render(cam, s) for s in (on, RenderSettings(), on))
    assert not np.array_equal(first.rgb, off.rgb)
    assert np.array_equal(first.rgb, again.rgb)
    assert np.array_equal(off.rgb, render(scene, cam, ViewFilter()).rgb)


def bright_splat() -> tuple[gb.Scene, gb.Camera]:
    """One splat whose base colour leaves [0, 1] on two channels, seen large enough that its support cut shows."""
    return splats([[0.0, 0.3, 4.0]], [0.2], [0.9], [[1.4, 0.3, -0.3]], rest=-0.3), camera(32, 32, 30.0)


@pytest.mark.parametrize(
    "vf,view",
    [(ViewFilter(sort_radial=True), radial_pair), (ViewFilter(dc_clamp=True, support=QUAD_SIGMAS), bright_splat)],
    ids=["radial", "clamp-support"],
)
def test_glsl_rules_match_the_cpu(gl, vf, view):
    scene, cam = view()
    ref = render(scene, cam, vf)
    assert not np.array_equal(ref.rgb, render(scene, cam, ViewFilter()).rgb)  # the rule shows in this view
    out = render(scene, cam, vf, backend="glsl")
    assert np.abs(out.rgb - ref.rgb).max() <= 1e-4 and np.abs(out.alpha - ref.alpha).max() <= 1e-4
