"""The benchmark: the zoom references, the SIMD path comparison, and
`gbviewer bench` end to end. Behaviour only: fields present and consistent, never wall-clock values."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import gbviewer as gb
from gbviewer import bench
from gbviewer.cli import build_parser, main
from gbviewer.cli.bench import BENCH_DEFAULTS, BENCH_FULL, resolve_bench_options
from gbviewer.model.camera import parse_rates
from gbviewer.outputs import metrics


def test_bench_sizes_align_with_every_zoom_factor(bundled_scene):
    (cam,) = bench.bench_views(bundled_scene, 1, 100, 75, multiple=8)
    assert (cam.width, cam.height) == (96, 72)
    low = cam.at_sampling_rate(1 / 8)
    assert metrics.box_downsample(np.zeros((cam.height, cam.width, 3)), 8).shape[:2] == (low.height, low.width)


def test_fidelity_references(bundled_scene):
    """Zoom-out: the mode at 1/k against the x1 scalar render box-downsampled by k. Zoom-in: the mode at k,
    box-downsampled by k, against its own x1 render."""
    (cam,) = bench.bench_views(bundled_scene, 1, 64, 48, multiple=4)
    s = gb.RenderSettings(gb.Mode.GAUSSIAN_BLENDING)
    rows = {(r.kind, r.rate): r for r in bench.measure_fidelity(bundled_scene, "b", [cam], [s], [4.0, 1.0, 0.25])}
    assert set(rows) == {("zoom-out", 0.25), ("zoom-in", 4.0)}
    x1_scalar = gb.render(bundled_scene, cam, "scalar").rgb
    low = gb.render(bundled_scene, cam.at_sampling_rate(0.25), "gaussian_blending").rgb
    assert rows["zoom-out", 0.25].psnr == pytest.approx(metrics.psnr(low, metrics.box_downsample(x1_scalar, 4)))
    high = metrics.box_downsample(gb.render(bundled_scene, cam.at_sampling_rate(4), "gaussian_blending").rgb, 4)
    x1 = gb.render(bundled_scene, cam, "gaussian_blending").rgb
    assert rows["zoom-in", 4.0].psnr == pytest.approx(metrics.psnr(high, x1))
    assert rows["zoom-in", 4.0].ssim == pytest.approx(metrics.ssim(high, x1))


def test_bench_command_end_to_end(tmp_path, capsys):
    out, plots = tmp_path / "b.json", tmp_path / "plots"
    args = [
        "bench",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar,gaussian_blending,supersample:2",
        "--views",
        "2",
        "--repeat",
        "2",
        "--size",
        "64x48",
        "--rates",
        "2,1,1/2",
        "--simd",
        "current",
        "--json",
        str(out),
        "--plots",
        str(plots),
        "--flicker-pairs",
        "2",
        "--flicker-size",
        "48x32",
    ]
    assert main(args) == 0
    doc = json.loads(out.read_text())
    assert {"cpu", "cores", "python"} <= set(doc["machine"])
    speed = doc["speed"]
    assert len(speed) == 3 * 3  # modes x rates on the cpu backend, one SIMD path
    fields = {
        "scene",
        "backend",
        "mode",
        "rate",
        "width",
        "height",
        "median_ms",
        "min_ms",
        "max_ms",
        "stages_ms",
        "visible",
        "sort_length",
        "evals_per_pixel",
        "mevals_per_s_per_core",
        "simd",
        "simd_requested",
        "blend_mevals_per_s_per_core",
        "exp_mevals_per_s_per_core",
        "simd_max_abs_diff",
    }
    assert all(set(r) >= fields and set(r["stages_ms"]) >= {"preprocess_ms", "sort_ms", "blend_ms"} for r in speed)
    assert {(r["mode"], r["rate"]) for r in speed} == {
        (m, k) for m in ("scalar", "gaussian_blending", "scalar:2") for k in (2.0, 1.0, 0.5)
    }
    assert {r["simd_requested"] for r in speed} == {doc["simd"]["in_use"]} == {bench.current_simd()}
    assert {r["simd"] for r in speed} <= set(doc["simd"]["paths"])
    fid = doc["fidelity"]
    assert {(r["kind"], r["rate"]) for r in fid} == {("zoom-in", 2.0), ("zoom-out", 0.5)}
    assert all(set(r) >= {"psnr", "ssim", "mode", "scene", "simd"} for r in fid)
    assert {r["ratio"] for r in doc["ratios"]} == {"gaussian_blending / scalar", "scalar:2 / gaussian_blending"}
    assert [p.suffix for p in plots.iterdir()] == [".png"]
    flicker = doc["flicker"]  # every mode, with the reference's floor
    assert [r["mode"] for r in flicker] == ["scalar", "gaussian_blending", "scalar:2"]
    assert all(
        r["flicker"] >= 0
        and r["floor"] > 0
        and r["pairs"] == 2
        and r["reference"] == "scalar:8"
        and (r["width"], r["height"]) == (48, 32)
        for r in flicker
    )
    assert "Flicker along a zoom" in capsys.readouterr().out
    assert main(args) == 2  # the JSON exists now: refused without --force
    assert "--force" in capsys.readouterr().err


# --- SIMD paths of the CPU backend: gbviewer._native.simd_paths / simd / set_simd / exp_rate, Frame.stats.simd


def test_native_simd_api_as_the_bench_uses_it(bundled_scene):
    paths = bench.simd_paths()
    assert paths[0] == "scalar" and set(paths) <= set(bench.SIMD_NAMES) and len(set(paths)) == len(paths)
    before = bench.current_simd()
    assert before in paths
    cam = gb.orbit_camera(bundled_scene, width=32, height=24)
    try:
        for p in paths:
            bench.set_simd(p)
            assert bench.current_simd() == p
            ran = gb.render(bundled_scene, cam, "scalar").stats.simd  # what ran: a mode may lack a vector path
            assert ran in paths and (ran == "scalar") >= (p == "scalar")
        with pytest.raises(ValueError):
            bench.set_simd("no-such-path")
    finally:
        bench.set_simd(before)
    rates = bench.exp_rates(paths, n=1 << 12, tries=1)
    assert set(rates) == set(paths) and all(math.isfinite(v) and v > 0 for v in rates.values())


def test_parse_simd():
    paths, cur = bench.simd_paths(), bench.current_simd()
    assert bench.parse_simd(None) == list(dict.fromkeys(["scalar", cur]))  # the default: scalar and the one in use
    assert bench.parse_simd("all") == paths
    assert bench.parse_simd("current") == [cur]
    assert bench.parse_simd(f"{paths[-1]},scalar,scalar") == list(dict.fromkeys(["scalar", paths[-1]]))  # scalar first
    with pytest.raises(gb.GBViewerError, match="unknown"):
        bench.parse_simd("sse9")
    for unsupported in set(bench.SIMD_NAMES) - set(paths):
        with pytest.raises(gb.GBViewerError, match="cannot run"):
            bench.parse_simd(unsupported)


def test_measure_speed_compares_every_path_and_restores_the_one_in_use(bundled_scene):
    paths, before = bench.simd_paths(), bench.current_simd()
    cams = bench.bench_views(bundled_scene, 2, 32, 24)
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending")
    units = []
    exp = bench.exp_rates(paths, n=1 << 12, tries=1)
    rows = bench.measure_speed(bundled_scene, "b", cams, settings, ["cpu"], [1.0, 0.5], 2, units.append, paths, exp)
    assert bench.current_simd() == before
    assert sum(units) == pytest.approx(bench.speed_cost(bundled_scene, cams, settings, ["cpu"], [1.0, 0.5], 2, paths))
    assert {(r.simd_requested, r.mode, r.rate) for r in rows} == {
        (p, s.spec, k) for p in paths for s in settings for k in (1.0, 0.5)
    }
    for r in rows:
        assert r.simd in paths and r.exp_mevals_per_s_per_core == pytest.approx(exp[r.simd] / 1e6)
        assert r.blend_mevals_per_s_per_core >= r.mevals_per_s_per_core > 0  # the blend is a part of the frame
        assert (r.simd_max_abs_diff is None) == (r.simd_requested == "scalar")
        if r.simd_requested == "scalar":
            assert r.simd == "scalar"
    by = {(r.simd_requested, r.mode, r.rate): r for r in rows}
    for (_p, mode, rate), r in by.items():  # the paths differ in the blend only: same splats, same tile lists
        assert (r.visible, r.sort_length) == (by["scalar", mode, rate].visible, by["scalar", mode, rate].sort_length)
    speedups = [x for x in bench.ratios(rows) if x["ratio"].startswith("blend speedup")]
    assert {(x["simd"], x["mode"], x["rate"]) for x in speedups} == {
        (p, s.spec, k) for p in paths[1:] for s in settings for k in (1.0, 0.5)
    }
    for x in speedups:
        base, r = by["scalar", x["mode"], x["rate"]], by[x["simd"], x["mode"], x["rate"]]
        assert x["value"] == pytest.approx(base.stages_ms["blend_ms"] / r.stages_ms["blend_ms"])
        assert x["ratio"] == f"blend speedup {x['simd']} over scalar"


def test_progress_units_add_up_to_the_totals(bundled_scene):
    cams = bench.bench_views(bundled_scene, 1, 32, 24, multiple=2)
    settings = gb.RenderSettings.parse_list("scalar,wsr")
    units = []
    bench.measure_fidelity(bundled_scene, "b", cams, settings, [2, 1, 0.5], progress=units.append)
    assert sum(units) == pytest.approx(bench.fidelity_cost(bundled_scene, cams, settings, [2, 1, 0.5]))
    units = []
    bench.measure_oit(bundled_scene, "b", cams, settings, flicker_frames=3, progress=units.append)
    assert sum(units) == pytest.approx(bench.oit_cost(bundled_scene, cams, settings, 3))
    units = []
    settings = gb.RenderSettings.parse_list("scalar,supersample:4")  # supersample:4 is the floor: rendered once
    bench.measure_stability(bundled_scene, "b", cams[0], settings, 2, (32, 24), progress=units.append)
    assert sum(units) == pytest.approx(bench.stability_cost(bundled_scene, cams[0], settings, 2, (32, 24)))


def test_bench_flicker_pairs_0_turns_the_measure_off():
    kwargs = dict(views=1, size=(32, 24), repeat=1, simd="current")
    settings = gb.RenderSettings.parse_list("scalar")
    assert bench.run_bench([gb.DEFAULT_SCENE], settings, [1.0], ["cpu"], flicker_pairs=0, **kwargs).flicker == []
    rows = bench.run_bench([gb.DEFAULT_SCENE], settings, [1.0], ["cpu"], flicker_pairs=1, **kwargs).flicker
    assert [(r.mode, r.pairs) for r in rows] == [("scalar", 1)]


def test_bench_simd_comparison_end_to_end(tmp_path, capsys):
    out = tmp_path / "b.json"
    paths = bench.simd_paths()
    args = [
        "bench",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar,gaussian_blending,supersample:2",
        "--views",
        "1",
        "--repeat",
        "1",
        "--size",
        "32x24",
        "--rates",
        "1",
        "--simd",
        "all",
        "--json",
        str(out),
    ]
    assert main(args) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    info = doc["simd"]
    assert info["paths"] == paths and info["measured"] == paths and info["in_use"] in paths
    assert set(info["exp_per_s_per_core"]) == set(paths) and all(v > 0 for v in info["exp_per_s_per_core"].values())
    assert {(r["simd_requested"], r["mode"]) for r in doc["speed"]} == {
        (p, m) for p in paths for m in ("scalar", "gaussian_blending", "scalar:2")
    }
    assert all(r["simd"] in paths for r in doc["speed"])
    names = {(x["ratio"], x.get("mode"), x["simd"]) for x in doc["ratios"]}
    for p in paths:
        assert {("gaussian_blending / scalar", None, p), ("scalar:2 / gaussian_blending", None, p)} <= names
    for p in paths[1:]:
        assert {
            (f"{k} speedup {p} over scalar", m, p)
            for k in ("blend", "frame")
            for m in ("scalar", "gaussian_blending", "scalar:2")
        } <= names
    assert f"SIMD paths {', '.join(paths)}" in printed and "exp per core" in printed
    if len(paths) > 1:
        assert "SIMD paths of the CPU backend" in printed


def test_bench_simd_errors(capsys):
    base = ["bench", str(gb.DEFAULT_SCENE), "--size", "16x16", "--rates", "1", "--views", "1", "--repeat", "1"]
    assert main(base + ["--simd", "sse9"]) == 2
    assert "unknown SIMD path" in capsys.readouterr().err
    for unsupported in set(bench.SIMD_NAMES) - set(bench.simd_paths()):
        assert main(base + ["--simd", unsupported]) == 2
        assert "cannot run" in capsys.readouterr().err
    assert main(base + ["--views", "0"]) == 2


def test_bench_presets():
    parse = lambda *a: resolve_bench_options(build_parser().parse_args(["bench", "s.ply", *a]))  # noqa: E731
    d = parse()
    assert (d.modes, d.rates, d.views, d.repeat, d.simd, d.size) == (
        BENCH_DEFAULTS["modes"],
        parse_rates(BENCH_DEFAULTS["rates"]),
        BENCH_DEFAULTS["views"],
        BENCH_DEFAULTS["repeat"],
        None,
        (640, 480),
    )
    f = parse("--full")
    assert (f.modes, f.views, f.repeat, f.simd) == tuple(BENCH_FULL[k] for k in ("modes", "views", "repeat", "simd"))
    assert f.rates == parse_rates(BENCH_FULL["rates"])
    e = parse("--full", "--modes", "scalar", "--rates", "1", "--repeat", "1", "--simd", "current")
    assert (e.modes, e.rates, e.views, e.repeat, e.simd) == ("scalar", [1.0], BENCH_FULL["views"], 1, "current")


def _run_all():
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "bench" / "run_all.py"
    spec = importlib.util.spec_from_file_location("run_all_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_run_all_targets_check_the_simd_targets():
    """bench/run_all.py's targets: the blend speedup of the vector path in use over the scalar path at 640x480
    (>= 6 for gaussian_blending, >= 4 for scalar), and gaussian_blending's frame ms there (median over the shared
    scenes <= 100), beside the existing ones; hand-made rows, no rendering."""
    ra = _run_all()

    def row(scene, mode, ms, blend, simd="avx2", rate=1.0, size=(320, 240)):
        return bench.SpeedRow(
            scene,
            "cpu",
            mode,
            rate,
            *size,
            ms,
            ms,
            ms,
            {"preprocess_ms": 0, "sort_ms": 0, "blend_ms": blend, "total_ms": ms},
            1,
            1,
            1.0,
            1.0,
            simd,
            simd,
        )

    names = ["bundled: a.ply", "b.ply", "c.ply"]
    speed, fidelity, simd = [], [], []
    for n in names:
        speed += [row(n, "scalar", 10, 8), row(n, "gaussian_blending", 14, 12), row(n, "scalar:3", 50, 45)]
        fidelity += [
            bench.FidelityRow(n, m, 0.125, "zoom-out", p, 0.9)
            for m, p in (("scalar", 20.0), ("gaussian_blending", 30.0), ("scalar:3", 29.0))
        ]
    for n, gb_vec, sc_vec in (("bundled: a.ply", 60, 10), ("b.ply", 90, 30), ("c.ply", 120, 20)):
        simd += [
            row(n, "gaussian_blending", 600, 600, "scalar", size=(640, 480)),
            row(n, "gaussian_blending", gb_vec, gb_vec, size=(640, 480)),
            row(n, "scalar", 100, 100, "scalar", size=(640, 480)),
            row(n, "scalar", sc_vec, sc_vec, size=(640, 480)),
        ]
    rows = ra.targets(speed, fidelity, names, simd, in_use="avx2")
    assert len(rows) == len(names) + 1 and all(len(r) == len(ra.target_header(in_use="avx2")) for r in rows)
    assert rows[0][1:5] == ["1.40 ok", "3.57 ok", "30.00 vs 29.00 ok", "+10.00 ok"]
    assert rows[0][5:] == ["10.0x ok", "10.0x ok", "60"]
    assert rows[1][5:] == ["6.7x ok", "3.3x MISSED", "90"]
    assert rows[2][5:] == ["5.0x MISSED", "5.0x ok", "120"]
    assert rows[3][0] == "median over the shared scenes" and rows[3][-1] == "105 MISSED"  # b and c, not bundled
    scalar_only = ra.targets(speed, fidelity, names, simd, in_use="scalar")
    assert all("MISSED" in r[5] and "MISSED" in r[6] for r in scalar_only[:-1])
