"""Frames beyond the memory budget render in parts and stitch (gbviewer.render.tiles; CpuRenderer.render_region).

A budget forced just under the whole frame's buffers sends a small image through the parts; the stitched frame must
equal the plain render bit for bit (rgb, alpha, evaluations, Gaussian Blending's window), in every mode the parts
support, supersampled or not, at sizes that are not multiples of the native tile, orthographic and with a
level-of-detail cut (the cut depends on the camera, which every part shares).
"""

from __future__ import annotations

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.render.budget import BUDGET_ENV, SPLAT_BYTES, frame_bytes
from gbviewer.render.tiles import STITCH_BYTES, WINDOW_STITCH_BYTES, plan_parts, region_step, render_tiled

W, H = 150, 90  # not multiples of 16: the parts' last columns and rows are partial tiles


def tight_budget(camera, settings, splats, parts=6) -> int:
    """A budget that holds the splats, the stitched image and about 1/parts of the frame's image buffers."""
    fixed = splats * SPLAT_BYTES + camera.width * camera.height * (STITCH_BYTES + WINDOW_STITCH_BYTES)
    return fixed + (frame_bytes(camera, settings, splats) - splats * SPLAT_BYTES) // parts


@pytest.fixture(scope="module")
def cpu(bundled_scene):
    return gb.get_renderer(bundled_scene, "cpu")


@pytest.mark.parametrize(
    "spec, projection",
    [
        ("scalar", "perspective"),
        ("gaussian_blending", "perspective"),
        ("scalar:3", "perspective"),
        ("gaussian_blending:2", "perspective"),
        ("mip", "perspective"),
        ("analytic", "perspective"),
        ("wsr", "perspective"),
        ("stochastic", "perspective"),
        ("stochastic_popfree:2", "perspective"),
        ("scalar+lod:4", "perspective"),
        ("gaussian_blending:2+lod:4", "perspective"),
        ("scalar", "orthographic"),
        ("gaussian_blending:4", "orthographic"),
        ("stopthepop:4:2", "perspective"),
    ],
)
def test_parts_equal_the_whole_frame_bit_for_bit(bundled_scene, cpu, spec, projection):
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=W, height=H, projection=projection)
    settings = gb.RenderSettings.parse(spec)
    if settings.mode == gb.Mode.GAUSSIAN_BLENDING:
        settings = gb.RenderSettings.parse(spec, debug="window")
    whole = cpu.render(cam, settings)
    budget = tight_budget(cam, settings, bundled_scene.num_splats)
    parts = plan_parts(cam, settings, bundled_scene.num_splats, budget)
    assert parts is not None and len(parts) >= 4  # the tiled path, in several parts
    step = region_step(settings)
    assert all(x % step == 0 and y % step == 0 for x, y, _, _ in parts)
    seen = []
    tiled = render_tiled(
        cpu,
        cam,
        settings,
        bundled_scene.num_splats,
        budget=budget,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert seen == [(i + 1, len(parts)) for i in range(len(parts))]
    assert np.array_equal(tiled.rgb, whole.rgb) and np.array_equal(tiled.alpha, whole.alpha)
    assert tiled.debug.keys() == whole.debug.keys()
    for name in whole.debug:
        assert np.array_equal(tiled.debug[name], whole.debug[name]), name
    assert tiled.stats.evaluations == whole.stats.evaluations


def test_whole_frame_when_it_fits_and_duplex_whole(bundled_scene, cpu):
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=W, height=H)
    s = gb.RenderSettings()
    assert plan_parts(cam, s, bundled_scene.num_splats, frame_bytes(cam, s, bundled_scene.num_splats)) is None
    with pytest.raises(gb.RenderError, match="duplex renders whole images only"):
        cpu.render_region(cam, gb.RenderSettings.parse("duplex"), (0, 0, 16, 16))


@pytest.mark.parametrize(
    "region, line",
    [
        ((8, 0, 16, 16), "x and y times supersample 1 must be multiples of 16"),
        ((0, 0, W + 1, 16), f"must be (x, y, w, h) inside the {W}x{H} image"),
        ((0, 0, 0, 16), f"must be (x, y, w, h) inside the {W}x{H} image"),
    ],
)
def test_bad_region_is_one_line(bundled_scene, cpu, region, line):
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=W, height=H)
    with pytest.raises(gb.RenderError) as exc:
        cpu.render_region(cam, gb.RenderSettings(), region)
    assert line in str(exc.value) and "\n" not in str(exc.value)


def test_cancel_between_parts_and_refusal(bundled_scene, cpu):
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=W, height=H)
    s = gb.RenderSettings.parse("scalar:2")
    token = gb.CancelToken()
    with pytest.raises(gb.RenderCancelled):
        render_tiled(
            cpu,
            cam,
            s,
            bundled_scene.num_splats,
            cancel=token,
            budget=tight_budget(cam, s, bundled_scene.num_splats),
            progress=lambda done, total: token.set(),
        )
    with pytest.raises(gb.RenderError) as exc:  # the splats alone exceed it: no part is small enough
        render_tiled(cpu, cam, s, bundled_scene.num_splats, budget=bundled_scene.num_splats * SPLAT_BYTES)
    assert "parts need" in str(exc.value) and BUDGET_ENV in str(exc.value) and "\n" not in str(exc.value)


def test_cli_render_beyond_the_budget(bundled_scene, tmp_path, monkeypatch):
    """`gbviewer render` refused such a frame before; now it renders it in parts, equal to the unlimited one."""
    args = [
        "render",
        str(gb.DEFAULT_SCENE),
        "--mode",
        "gaussian_blending:3",
        "--width",
        str(W),
        "--height",
        str(H),
        "--backend",
        "cpu",
    ]
    assert main(args + ["--out", str(tmp_path / "whole.npy")]) == 0
    cam = gb.orbit_camera(bundled_scene, 30, 20, width=W, height=H)
    budget = tight_budget(cam, gb.RenderSettings.parse("gaussian_blending:3"), bundled_scene.num_splats)
    monkeypatch.setenv(BUDGET_ENV, str(budget))
    assert main(args + ["--out", str(tmp_path / "parts.npy")]) == 0
    assert np.array_equal(np.load(tmp_path / "parts.npy"), np.load(tmp_path / "whole.npy"))
