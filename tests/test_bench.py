"""Benchmark metrics against hand-computed cases, the zoom references, and `gbviewer bench` end to end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import gbviewer as gb
from gbviewer import bench
from gbviewer.cli import main


def test_box_downsample_hand_case_and_ragged_edges():
    img = np.arange(5 * 7, dtype=np.float64).reshape(5, 7)  # 5x7 with k=2: the last row and column are cropped
    out = bench.box_downsample(img, 2)
    assert out.shape == (2, 3)
    assert out[0, 0] == (0 + 1 + 7 + 8) / 4 and out[1, 2] == (18 + 19 + 25 + 26) / 4
    rgb = np.stack([img, 2 * img, 3 * img], axis=2)
    np.testing.assert_array_equal(bench.box_downsample(rgb, 2)[..., 2], 3 * out)


def test_psnr_hand_cases():
    a = np.zeros((4, 4, 3))
    assert bench.psnr(a, a + 0.1) == pytest.approx(20.0)  # mse 0.01
    assert bench.psnr(a, a) == math.inf
    assert bench.psnr(a - 5, a + 0.1) == pytest.approx(20.0)  # both clipped to [0, 1] first


def test_ssim_hand_cases():
    x = np.random.default_rng(0).uniform(size=(32, 32, 3))
    assert bench.ssim(x, x) == pytest.approx(1.0)
    # constant images: SSIM = (2ab + C1) / (a^2 + b^2 + C1), C1 = (0.01)^2
    a, b, c1 = 0.5, 0.25, 1e-4
    assert bench.ssim(np.full((16, 16, 3), a), np.full((16, 16, 3), b)) == pytest.approx((2 * a * b + c1) / (a * a + b * b + c1), abs=1e-9)
    assert math.isnan(bench.ssim(x[:10, :10], x[:10, :10]))  # the 11x11 window does not fit


def test_bench_sizes_align_with_every_zoom_factor(bundled_scene):
    (cam,) = bench.bench_views(bundled_scene, 1, 100, 75, multiple=8)
    assert (cam.width, cam.height) == (96, 72)
    low = cam.at_sampling_rate(1 / 8)
    assert bench.box_downsample(np.zeros((cam.height, cam.width, 3)), 8).shape[:2] == (low.height, low.width)


def test_fidelity_references(bundled_scene):
    """Zoom-out: the mode at 1/k against the x1 scalar render box-downsampled by k. Zoom-in: the mode at k,
    box-downsampled by k, against its own x1 render."""
    (cam,) = bench.bench_views(bundled_scene, 1, 64, 48, multiple=4)
    s = gb.RenderSettings(gb.Mode.GAUSSIAN_BLENDING)
    rows = {(r.kind, r.rate): r for r in bench.measure_fidelity(bundled_scene, "b", [cam], [s], [4.0, 1.0, 0.25])}
    assert set(rows) == {("zoom-out", 0.25), ("zoom-in", 4.0)}
    x1_scalar = gb.render(bundled_scene, cam, "scalar").rgb
    low = gb.render(bundled_scene, cam.at_sampling_rate(0.25), "gaussian_blending").rgb
    assert rows["zoom-out", 0.25].psnr == pytest.approx(bench.psnr(low, bench.box_downsample(x1_scalar, 4)))
    high = bench.box_downsample(gb.render(bundled_scene, cam.at_sampling_rate(4), "gaussian_blending").rgb, 4)
    x1 = gb.render(bundled_scene, cam, "gaussian_blending").rgb
    assert rows["zoom-in", 4.0].psnr == pytest.approx(bench.psnr(high, x1))
    assert rows["zoom-in", 4.0].ssim == pytest.approx(bench.ssim(high, x1))


def test_bench_command_end_to_end(tmp_path, capsys):
    out, plots = tmp_path / "b.json", tmp_path / "plots"
    args = ["bench", str(gb.DEFAULT_SCENE), "--modes", "scalar,gaussian_blending,supersample:2", "--views", "2",
            "--repeat", "2", "--size", "64x48", "--rates", "2,1,1/2", "--json", str(out), "--plots", str(plots)]
    assert main(args) == 0
    doc = json.loads(out.read_text())
    assert {"cpu", "cores", "python"} <= set(doc["machine"])
    speed = doc["speed"]
    assert len(speed) == 3 * 3  # modes x rates on the cpu backend
    fields = {"scene", "backend", "mode", "rate", "width", "height", "median_ms", "min_ms", "max_ms", "stages_ms",
              "visible", "sort_length", "evals_per_pixel", "mevals_per_s_per_core"}
    assert all(set(r) >= fields and set(r["stages_ms"]) >= {"preprocess_ms", "sort_ms", "blend_ms"} for r in speed)
    assert {(r["mode"], r["rate"]) for r in speed} == {(m, k) for m in ("scalar", "gaussian_blending", "scalar:2")
                                                       for k in (2.0, 1.0, 0.5)}
    fid = doc["fidelity"]
    assert {(r["kind"], r["rate"]) for r in fid} == {("zoom-in", 2.0), ("zoom-out", 0.5)}
    assert all(set(r) >= {"psnr", "ssim", "mode", "scene"} for r in fid)
    assert {r["ratio"] for r in doc["ratios"]} == {"gaussian_blending / scalar", "scalar:2 / gaussian_blending"}
    assert [p.suffix for p in plots.iterdir()] == [".png"]
    assert main(args) == 2  # the JSON exists now: refused without --force
    assert "--force" in capsys.readouterr().err
