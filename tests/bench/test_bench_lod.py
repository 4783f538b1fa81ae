"""`gbviewer bench --lod`: the LOD variants measured beside the modes (speed and zoom fidelity against the same
references), and the quality-against-cost panel of the plots."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

import gbviewer as gb
from gbviewer.bench.fidelity import FidelityRow
from gbviewer.bench.report import line_style, pyplot, quality_cost
from gbviewer.cli import main


def test_bench_measures_the_lod_variants(tmp_path):
    out = tmp_path / "b.json"
    argv = [
        "bench",
        str(gb.DEFAULT_SCENE),
        "--modes",
        "scalar",
        "--lod",
        "2",
        "--rates",
        "1,1/2",
        "--views",
        "1",
        "--repeat",
        "1",
        "--size",
        "32x24",
        "--simd",
        "current",
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    fid = {(r["mode"], r["rate"]) for r in doc["fidelity"]}
    assert fid == {("scalar", 0.5), ("scalar+lod:2", 0.5)}
    assert {(r["mode"], r["rate"]) for r in doc["speed"]} >= {("scalar+lod:2", 1.0), ("scalar+lod:2", 0.5)}


def test_quality_cost_plots_psnr_against_the_fastest_time():
    pytest.importorskip("matplotlib", reason="the [eval] extra")
    fid = [
        FidelityRow("s", m, rate, "zoom-out", psnr, 0.9)
        for m, rate, psnr in [("scalar", 0.5, 30.0), ("scalar", 0.25, 25.0), ("scalar+lod:1", 0.25, 27.0)]
    ]
    fid.append(FidelityRow("s", "scalar", 2.0, "zoom-in", 40.0, 0.99))  # not a zoom-out point
    speed = [
        SimpleNamespace(mode=m, rate=rate, median_ms=ms)
        for m, rate, ms in [
            ("scalar", 0.5, 9.0),
            ("scalar", 0.5, 7.0),
            ("scalar", 0.25, 5.0),
            ("scalar+lod:1", 0.25, 2.0),
            ("scalar", 2.0, 50.0),
        ]
    ]
    plt = pyplot()
    fig, ax = plt.subplots()
    quality_cost(ax, "s", speed, fid, {m: line_style(i) for i, m in enumerate(["scalar", "scalar+lod:1"])})
    lines = {line.get_label(): (list(line.get_xdata()), list(line.get_ydata())) for line in ax.get_lines()}
    plt.close(fig)
    assert lines == {"scalar": ([5.0, 7.0], [25.0, 30.0]), "scalar+lod:1": ([2.0], [27.0])}
