"""The comparison figure (gbviewer.outputs.figure.compare_figure; `gbviewer compare`): cells are exactly the renders,
PSNR against the zoom-out reference, inset, refusal to overwrite."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import OUTPUT_H as H
from helpers import OUTPUT_W as W
from PIL import Image

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.outputs import differences, figure
from gbviewer.outputs.figure import to_uint8, upscale_nearest
from gbviewer.outputs.metrics import box_downsample, psnr


def test_compare_cells_equal_the_renders(bundled_scene, output_view):
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    rates = [2.0, 1.0, 0.5, 0.25]
    cmp = figure.compare_figure(bundled_scene, output_view, settings, rates)
    img = np.asarray(cmp.image)
    cap = cmp.layout.caption_height
    assert cap > 0 and img.shape[:2] == (4 * (H + cap) + 3 * 4, 2 * W + 4)
    ref = gb.render(bundled_scene, output_view, "scalar").rgb
    for r, rate in enumerate(rates):
        for c, s in enumerate(settings):
            rgb = gb.get_renderer(bundled_scene).render(output_view.at_sampling_rate(rate), s).rgb
            x, y = cmp.layout.origin(r, c)
            np.testing.assert_array_equal(img[y : y + H, x : x + W], upscale_nearest(to_uint8(rgb), H, W))
            p = cmp.psnr[r][c]
            if rate > 1:
                assert p is None
            elif rate == 1 and s.mode == gb.Mode.SCALAR:
                assert p == math.inf
            else:
                assert p == pytest.approx(psnr(rgb, box_downsample(ref, round(1 / rate))))


def test_cli_compare_with_inset_and_refusal(tmp_path, output_view, bundled_scene, capsys):
    out = tmp_path / "fig.png"
    args = [
        "compare",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "gaussian_blending",
        "--rates",
        "1,1/4",
        "--width",
        str(W),
        "--height",
        str(H),
        "--orbit",
        "30,20,0",
        "--inset",
        "10,10,16,12",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert "PSNR" in capsys.readouterr().out
    img = np.asarray(Image.open(out).convert("RGB"))
    gb_only = [gb.RenderSettings(gb.Mode.GAUSSIAN_BLENDING, precision="fast")]  # compare's default: fast
    cmp_layout = figure.compare_figure(bundled_scene, output_view, gb_only, [1.0]).layout
    cap = cmp_layout.caption_height
    assert img.shape[:2] == (2 * (H + cap) + 4, W)
    for r, rate in enumerate((1.0, 0.25)):
        rgb = gb.render(bundled_scene, output_view.at_sampling_rate(rate), "gaussian_blending+fast", backend="auto").rgb
        y = r * (H + cap + 4)
        # rows between the region's outline (y <= 22) and the magnified inset (bottom-right, from y = 41)
        np.testing.assert_array_equal(img[y + 24 : y + 40], upscale_nearest(to_uint8(rgb), H, W)[24:40])
        assert not np.array_equal(img[y + 41 : y + H], upscale_nearest(to_uint8(rgb), H, W)[41:])  # inset drawn
    before = out.read_bytes()
    assert main(args) == 2 and out.read_bytes() == before
    assert "--force" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]


@pytest.mark.parametrize("kind", ["first", "ref"])
def test_compare_diff_rows_show_the_colour_mapped_differences_and_the_colour_bar(bundled_scene, output_view, kind):
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    rates = [1.0, 0.25]
    cmp = figure.compare_figure(bundled_scene, output_view, settings, rates, diff=kind)
    plain = figure.compare_figure(bundled_scene, output_view, settings, rates)
    img = np.asarray(cmp.image)
    cap = cmp.layout.caption_height
    grid_h = 4 * (H + cap) + 3 * 4  # each rate's row, then its differences
    assert cmp.layout.rows == 4 and img.shape[1] == 2 * W + 4 and img.shape[0] > grid_h
    assert np.asarray(plain.image).shape[0] == 2 * (H + cap) + 4
    renderer = gb.get_renderer(bundled_scene)
    ds = []
    for r, rate in enumerate(rates):
        cam = output_view.at_sampling_rate(rate)
        rgbs = [renderer.render(cam, s).rgb for s in settings]
        ref = rgbs[0] if kind == "first" else gb.render(bundled_scene, cam, "scalar", supersample=8).rgb
        for c, rgb in enumerate(rgbs):
            x, y = cmp.origin(r, c)  # the renders, as without --diff
            np.testing.assert_array_equal(img[y : y + H, x : x + W], upscale_nearest(to_uint8(rgb), H, W))
            d = differences.signed_difference(rgb, ref)
            ds.append((r, c, d))
            assert cmp.diff.psnr[r][c] == psnr(rgb, ref)
    scale = max(differences.robust_scale(d) for r, c, d in ds if kind == "ref" or c > 0)
    assert cmp.diff.scale == scale
    for r, c, d in ds:
        x, y = cmp.origin(r, c, diff=True)
        expected = upscale_nearest(to_uint8(differences.colour_difference(d, scale)), H, W)
        np.testing.assert_array_equal(img[y : y + H, x : x + W], expected)
        if kind == "first" and c == 0:
            assert cmp.diff.psnr[r][c] == math.inf
            assert (expected == to_uint8(differences.DIVERGING[5])).all()  # zero everywhere
    bx, by, bw, bh = cmp.bar
    assert by > grid_h
    np.testing.assert_array_equal(img[by : by + bh, bx : bx + bw], to_uint8(differences.colour_bar(bw, bh)))
    with pytest.raises(gb.GBViewerError, match="expected one of first, ref"):
        figure.compare_figure(bundled_scene, output_view, settings, rates, diff="second")


def test_cli_compare_diff(tmp_path, capsys):
    out = tmp_path / "fig.png"
    args = [
        "compare",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar,gaussian_blending",
        "--rates",
        "1/4",
        "--width",
        str(W),
        "--height",
        str(H),
        "--orbit",
        "30,20,0",
        "--diff",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "mean over RGB" in printed and "vs scalar" in printed
    h = np.asarray(Image.open(out)).shape[0]
    assert main([*args[:-3], "--diff", "ref", "--out", str(tmp_path / "ref.png")]) == 0
    assert "vs scalar 8x8" in capsys.readouterr().out
    assert np.asarray(Image.open(tmp_path / "ref.png")).shape[0] == h
    assert main([*args[:-3], "--diff", "none", "--out", str(tmp_path / "x.png")]) == 2
    assert "--diff" in capsys.readouterr().err and not (tmp_path / "x.png").exists()
