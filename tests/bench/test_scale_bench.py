"""The scale benchmark's tiled scenes (`gbviewer.bench.scale_scene`) and its measurements (`gbviewer.bench.scale`),
on a 12-splat source: the tiles are the source moved on a grid with SH padded to degree 3, the file is the same
bytes wherever it is built, it is reused while its record matches and rebuilt when not."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import gbviewer as gb
from gbviewer.bench.scale import run_scale
from gbviewer.bench.scale_scene import grid_offsets, padded, tiled_scene

SOURCE = Path(__file__).parents[1] / "io" / "fuzz" / "seeds" / "inria" / "sh1.ply"


def test_tiles_are_the_source_on_a_grid_with_sh_degree_3(tmp_path):
    path = tiled_scene(5, SOURCE, tmp_path, log=lambda _: None)
    assert path.parent == tmp_path
    src, tiled = padded(gb.load(SOURCE)), gb.load(path)
    n = src.num_splats
    assert tiled.num_splats == 5 * n and tiled.sh_degree == 3 and src.sh_degree == 3
    offsets = grid_offsets(src, 5)
    assert len({tuple(o) for o in offsets}) == 5 and (offsets[:, 1] == 0).all()
    for t in range(5):
        rows = slice(t * n, (t + 1) * n)
        np.testing.assert_array_equal(tiled.means[rows], src.means + offsets[t])
        for name in ("scales", "quats", "opacities", "sh"):
            np.testing.assert_array_equal(getattr(tiled, name)[rows], getattr(src, name), err_msg=name)
    assert (tiled.sh[:, 4:] == 0).all()  # the source's degree 1, padded with zeros


def test_built_deterministically_and_reused_while_the_record_matches(tmp_path):
    logs: list[str] = []
    a = tiled_scene(3, SOURCE, tmp_path / "a", log=logs.append)
    b = tiled_scene(3, SOURCE, tmp_path / "b", log=logs.append)
    assert a.read_bytes() == b.read_bytes() and len(logs) == 2
    record = json.loads(a.with_suffix(".json").read_text())
    assert record["bytes"] == a.stat().st_size and record["params"]["tiles"] == 3
    stamp = a.stat().st_mtime_ns
    assert tiled_scene(3, SOURCE, tmp_path / "a", verify=True, log=logs.append) == a and len(logs) == 2
    assert a.stat().st_mtime_ns == stamp
    a.write_bytes(a.read_bytes()[:-4])  # a damaged file no longer matches its record: rebuilt
    tiled_scene(3, SOURCE, tmp_path / "a", log=logs.append)
    assert len(logs) == 3 and a.read_bytes() == b.read_bytes()


def test_run_scale_reports_every_measurement(tmp_path):
    path = tiled_scene(2, SOURCE, tmp_path, log=lambda _: None)
    r = run_scale(path, 1, ["scalar", "gaussian_blending"], [1.0, 0.5], [0.0], width=32, height=18, log=lambda _: None)
    assert r["splats"] == 24 and r["load"]["arrays_bytes"] == 24 * (3 + 3 + 4 + 1 + 48) * 4
    assert r["load"]["raw_s"] > 0 and r["load"]["peak_rss_above_baseline"] > 0
    assert [(s["mode"], s["rate"], s["width"]) for s in r["stages"]] == [
        ("scalar", 1.0, 32),
        ("scalar", 0.5, 16),
        ("gaussian_blending", 1.0, 32),
        ("gaussian_blending", 0.5, 16),
    ]
    panes = r["two_pane"]["panes"]
    assert [p["mode"] for p in panes] == ["scalar", "gaussian_blending"]
    assert [p["stage_reused"] for p in panes] == [False, True]
    assert panes[0]["shared_ms"] > 0 and panes[1]["shared_ms"] == 0 == r["two_pane"]["second_over_first"]
    assert all(p["own_ms"] > 0 for p in panes) and r["two_pane"]["before_blend_ratio"] > 0
    assert [p["order_reused"] for p in panes] == [False, True]
    cancels = r["cancel"]
    assert [(c["stage"], c["supersample"]) for c in cancels] == [
        ("preprocess", 1),
        ("order+bin", 1),
        ("blend", 1),
        ("", 1),
        ("preprocess", 4),
        ("order+bin", 4),
        ("blend", 4),
    ]
    assert all(c["finished"] != (c["latency_ms"] is not None) for c in cancels)
