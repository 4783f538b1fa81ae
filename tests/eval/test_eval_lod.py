"""`gbviewer eval --lod`: each mode is also evaluated at the level-of-detail cut, against the same photos, with its
render time."""

from __future__ import annotations

import json

from dataset_builders import shots, write_blender

import gbviewer as gb
from gbviewer.cli import main


def test_eval_lod_rows_beside_the_modes(bundled_scene, tmp_path):
    data = write_blender(tmp_path / "blender", shots(bundled_scene, vary=False))
    out = tmp_path / "e.json"
    argv = [
        "eval",
        f"{gb.DEFAULT_SCENE}:{data}",
        "--modes",
        "scalar",
        "--lod",
        "3",
        "--rates",
        "1,1/2",
        "--backend",
        "cpu",
        "--cache",
        str(tmp_path / "c"),
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    table = doc["scenes"][0]["table"]
    rows = {(row["mode"], row["rate"]): row for row in table}
    assert set(rows) == {(m, r) for m in ("scalar", "scalar+lod:3") for r in (1.0, 0.5)}
    assert all(row["render_ms"] > 0 and 0 < row["psnr"] < 99 for row in table)
    assert rows["scalar", 0.5]["psnr"] != rows["scalar+lod:3", 0.5]["psnr"]  # the cut is drawn, not the scene
