"""Viewer presets (gbviewer/render/presets.py): each one's rule, as its viewer's code states it, against hand-checked
values of one splat at one pixel and against the float64 reference re-implementing the rule (reference_preprocess,
`view_filter`); presets with the same parameters as a built-in mode render it bit for bit; the GLSL port agrees
with the CPU within the cross-backend tolerance."""

from __future__ import annotations

import math
from dataclasses import asdict, replace

import numpy as np
import pytest
from glsl_helpers import compare
from helpers import random_view
from reference import reference_render

import gbviewer as gb
from gbviewer.model.scene import SH_C0
from gbviewer.render import RenderSettings, create_renderer
from gbviewer.render.presets import PRESETS, differences

TOL = 1e-4  # as tests/render/test_render_reference.py (float32 noise is ~1e-6; a wrong rule shows at >= 1e-3)
BACKGROUND = (0.1, 0.5, 0.9)


def render(scene: gb.Scene, cam: gb.Camera, spec: str, backend: str = "cpu", **kwargs) -> gb.Frame:
    r = create_renderer(backend)
    r.upload(scene)
    try:
        return r.render(cam, RenderSettings.parse(spec, **kwargs))
    finally:
        r.release()


def one_splat(variance: float, opacity: float = 0.5, sh_rest: float = 0.0) -> tuple[gb.Scene, gb.Camera]:
    """An isotropic splat whose projected variance is `variance` px^2 (before any filter), centred on pixel (16, 16)'s
    centre; SH degree 1 with every rest coefficient `sh_rest`."""
    f, z = 100.0, 5.0
    s = math.sqrt(variance) * z / f
    sh = np.zeros((1, 4, 3))
    sh[0, 0] = (0.3, 0.2, 0.1)
    sh[0, 1:] = sh_rest
    scene = gb.Scene.from_arrays([[0.0, 0.0, z]], [[s, s, s]], [[1.0, 0, 0, 0]], [opacity], sh)
    return scene, gb.Camera(32, 32, f, f, 16.5, 16.5, np.eye(3), np.zeros(3))


# (preset, projected variance px^2, alpha at the centre pixel, alpha one pixel to the right), worked by hand from
# each rule with opacity 0.5: inria adds 0.3 (variance 1.3: 0.5 exp(-1/2.6)); gsplat-antialiased and spark add 0.3
# and scale the opacity by sqrt(det / det'') = 1/1.3; supersplat adds 0.3 and drops the splat when the larger
# eigenvalue is below 0.5 px^2 (variance 0.1: 0.4, dropped); antimatter15 adds nothing (0.5 exp(-1/2)).
HAND = [
    ("inria", 1.0, 0.5, 0.5 * math.exp(-0.5 / 1.3)),
    ("gsplat-antialiased", 1.0, 0.5 / 1.3, 0.5 / 1.3 * math.exp(-0.5 / 1.3)),
    ("spark", 1.0, 0.5 / 1.3, 0.5 / 1.3 * math.exp(-0.5 / 1.3)),
    ("supersplat", 1.0, 0.5, 0.5 * math.exp(-0.5 / 1.3)),
    ("supersplat", 0.1, 0.0, 0.0),
    ("inria", 0.1, 0.5, 0.5 * math.exp(-0.5 / 0.4)),
    ("antimatter15", 1.0, 0.5, 0.5 * math.exp(-0.5)),
    ("gsplat-antialiased", 0.1, 0.5 * 0.1 / 0.4, 0.5 * 0.1 / 0.4 * math.exp(-0.5 / 0.4)),
]


@pytest.mark.parametrize("preset,variance,centre,right", HAND)
def test_one_splat_one_pixel_hand_checked(preset, variance, centre, right):
    scene, cam = one_splat(variance)
    frame = render(scene, cam, f"preset:{preset}")
    assert frame.alpha[16, 16] == pytest.approx(centre, abs=2e-6)
    assert frame.alpha[16, 17] == pytest.approx(right, abs=2e-6)
    colour = SH_C0 * np.array([0.3, 0.2, 0.1]) + 0.5
    np.testing.assert_allclose(frame.rgb[16, 16], colour * centre, atol=2e-6)


def test_sh_bands_follow_the_preset():
    """antimatter15 shows the DC colour only; inria all bands (the splat sits on the axis: direction (0, 0, 1), so
    only the z band, coefficient 2 of degree 1, adds SH_C1 * rest)."""
    scene, cam = one_splat(1.0, sh_rest=0.4)
    dc = SH_C0 * np.array([0.3, 0.2, 0.1]) + 0.5
    np.testing.assert_allclose(render(scene, cam, "preset:antimatter15").rgb[16, 16], dc * 0.5, atol=2e-6)
    full = render(scene, cam, "preset:inria").rgb[16, 16]
    np.testing.assert_allclose(full, (dc + 0.4886025119029199 * 0.4) * 0.5, atol=2e-6)


@pytest.mark.parametrize("name", [n for n, p in PRESETS.items() if p.mode == "scalar"])  # stochastic: its own test
@pytest.mark.parametrize("seed", [31, 32])
def test_presets_match_the_float64_reference(name, seed):
    preset = PRESETS[name]
    scene, cam = random_view(seed, sh_degree=3)
    if preset.sh_degree < 3:
        scene = gb.Scene.from_arrays(
            scene.means, scene.scales, scene.quats, scene.opacities, scene.sh[:, : (preset.sh_degree + 1) ** 2]
        )
    for supersample in (1, 2):
        frame = render(scene, cam, f"preset:{name}:{supersample}", background=BACKGROUND)
        rgb, alpha, ties = reference_render(
            scene,
            cam,
            "scalar",
            supersample,
            background=BACKGROUND,
            return_ties=True,
            view_filter=asdict(preset.view_filter),
        )
        err = np.maximum(np.abs(frame.rgb - rgb).max(-1), np.abs(frame.alpha - alpha))
        assert np.where(ties, 0.0, err).max() <= TOL, f"{name} ss{supersample}: {err.max():.3e}"
        assert ties.sum() <= 4 and err.max() <= 2e-2
        assert (alpha > 0.05).mean() > 0.3


def test_the_reference_tells_the_presets_apart():
    """The reference check above can fail: each preset's rule moves the image by more than its tolerance."""
    scene, cam = random_view(31, sh_degree=0)
    plain = reference_render(scene, cam, "scalar")[0]
    for name in ("gsplat-antialiased", "supersplat", "antimatter15"):
        other = reference_render(scene, cam, "scalar", view_filter=asdict(PRESETS[name].view_filter))[0]
        assert np.abs(other - plain).max() > 10 * TOL, name


def test_presets_with_a_modes_parameters_render_it_bit_for_bit():
    scene, cam = random_view(33, sh_degree=3)
    a, b = render(scene, cam, "preset:inria"), render(scene, cam, "scalar")
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)
    # spark is gsplat-antialiased's filter plus its rules (test_preset_rules.py)
    rules_off = dict(dc_clamp=False, support=0.0, sort_radial=False)
    assert replace(PRESETS["spark"].view_filter, **rules_off) == PRESETS["gsplat-antialiased"].view_filter


def test_differences_name_the_parameters():
    s = {n: RenderSettings.parse(f"preset:{n}") for n in PRESETS}
    assert differences(s["inria"], s["gsplat-antialiased"]) == ["compensate 0 vs 1"]
    assert differences(s["supersplat"], s["antimatter15"]) == [
        "dilation 0.3 vs 0",
        "cull_lambda 0.5 vs 0",
        "dc_clamp 0 vs 1",
        "SH 3 vs 0",
    ]
    assert differences(s["inria"], RenderSettings.parse("gaussian_blending")) == ["mode scalar vs gaussian_blending"]


@pytest.mark.parametrize("name", ["gsplat-antialiased", "supersplat", "spark", "antimatter15"])
def test_glsl_presets_match_the_cpu(gl, name):
    scene, cam = random_view(34, n=400, sh_degree=3, W=96, H=80)
    compare(scene, cam, f"preset:{name}")
    compare(scene, cam, f"preset:{name}:2")
