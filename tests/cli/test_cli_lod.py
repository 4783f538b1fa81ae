"""The command line's level of detail: `--lod PX` and the `MODE+lod:TAU` spec on render, compare, bench, eval,
video and flicker; what it renders is `RenderSettings(lod=PX)`'s image; bad values are one line and exit status 2."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import patch_commands

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.cli.options import with_lod
from gbviewer.outputs.figure import drawable

COMMON = ["--width", "48", "--height", "36", "--orbit", "10,20,0", "--backend", "cpu"]


def test_render_lod_is_the_settings_image(tmp_path, capsys):
    out = tmp_path / "a.npy"
    assert main(["render", str(gb.DEFAULT_SCENE), *COMMON, "--lod", "4", "--out", str(out)]) == 0
    scene = gb.load(gb.DEFAULT_SCENE)
    cam = gb.orbit_camera(scene, 10, 20, width=48, height=36)
    lod = gb.render(scene, cam, "scalar", backend="cpu", lod=4)
    np.testing.assert_array_equal(np.load(out), lod.rgb)
    assert not np.array_equal(lod.rgb, gb.render(scene, cam, "scalar", backend="cpu").rgb)  # the cut is coarser
    assert "LOD \u03c4=4 px" in capsys.readouterr().out
    spec = tmp_path / "b.npy"  # the same through the spec
    assert main(["render", str(gb.DEFAULT_SCENE), *COMMON, "--mode", "scalar+lod:4", "--out", str(spec)]) == 0
    np.testing.assert_array_equal(np.load(spec), lod.rgb)


def test_with_lod_adds_each_modes_variant_once():
    settings = gb.RenderSettings.parse_list("scalar,gaussian_blending+lod:2,scalar:3")
    assert [s.spec for s in with_lod(settings, 1.0)] == [
        "scalar",
        "scalar+lod:1",
        "gaussian_blending+lod:2",
        "scalar:3",
        "scalar:3+lod:1",
    ]
    assert with_lod(settings, None) is settings
    assert [s.spec for s in with_lod(gb.RenderSettings.parse_list("scalar,scalar+lod:1"), 1.0)] == [
        "scalar",
        "scalar+lod:1",
    ]


@pytest.mark.parametrize("cmd", ["render", "compare", "bench", "eval", "video", "flicker"])
@pytest.mark.parametrize("value", ["-1", "nan", "x", "1e9"])
def test_bad_lod_one_line_exit_2(cmd, value, capsys, monkeypatch):
    patch_commands(monkeypatch, "load", lambda *a: pytest.fail("loaded a scene despite a bad option"))
    assert main([cmd, "s.ply", f"--lod={value}"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith(f"gbviewer {cmd}: error: argument --lod: "), err


@pytest.mark.parametrize(
    "spec, says",
    [
        ("scalar+lod:x", "LOD pixels 'x' is not a number"),
        ("scalar+lod:-2", "lod"),
        ("scalar+fog", "expected MODE[:N][+fast|+exact][+lod[:TAU]]"),
    ],
)
def test_bad_lod_spec_one_line_exit_2(spec, says, tmp_path, capsys):
    argv = ["compare", str(gb.DEFAULT_SCENE), "--modes", spec, "--out", str(tmp_path / "c.png")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and says in err, err
    assert not list(tmp_path.iterdir())


def test_compare_lod_adds_the_lod_columns_with_spelled_out_tau(tmp_path, capsys):
    out = tmp_path / "c.png"
    argv = [
        "compare",
        str(gb.DEFAULT_SCENE),
        *COMMON,
        "--modes",
        "scalar",
        "--lod",
        "2",
        "--rates",
        "1,1/2",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "2 rates x 2 modes" in text and "scalar LOD \u03c4=2 px" in text
    assert drawable("scalar LOD \u03c4=2 px, 10 of 20 splats") == "scalar LOD tau=2 px, 10 of 20 splats"
