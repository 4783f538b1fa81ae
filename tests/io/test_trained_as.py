"""The training mode a file declares (gbviewer.io.trained_as): each signal read from a file the test writes, the
conflict rule, and `convert` keeping it as the PLY comment."""

from __future__ import annotations

import json

import numpy as np
import pytest
from encoders import encode_spz, random_params, sog_files, write_sog

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.io.trained_as import ANTIALIASED, MIP_3D, THREEDGS, UNKNOWN, describe
from gbviewer.io.write import inria_columns, ply_header


def write_ply(path, comments=(), filter_3d=False):
    s = random_params(6, seed=3)
    scene = gb.Scene.from_arrays(
        s["means"],
        s["scales"],
        s["quats"],
        s["opacities"],
        s["sh"],
        np.full(6, 0.01, np.float32) if filter_3d else None,
    )
    cols = inria_columns(scene)
    body = np.stack(list(cols.values()), axis=1).astype("<f4")
    path.write_bytes(ply_header(6, list(cols), tuple(comments)) + body.tobytes())
    return path


def trained(scene):
    return scene.meta["trained_as"], scene.meta["trained_as_source"], scene.meta["trained_as_conflict"]


@pytest.mark.parametrize(
    "comment, expected",
    [
        ("SplatRenderMode: mip", ANTIALIASED),
        ("SplatRenderMode: default", THREEDGS),
        ("  splatrendermode:MIP ", ANTIALIASED),
        ("SplatRenderMode: 2dgs", UNKNOWN),
    ],
)
def test_ply_comment(tmp_path, comment, expected):
    scene = gb.load(write_ply(tmp_path / "s.ply", ["Exported from Brush", comment]))
    assert trained(scene) == (expected, f"PLY comment 'SplatRenderMode: {comment.split(':')[1].strip()}'", None)


def test_no_signal_is_unknown(tmp_path):
    scene = gb.load(write_ply(tmp_path / "s.ply", ["Vertical axis: y"]))
    assert trained(scene) == (UNKNOWN, "the file does not say", None)
    assert describe(scene.meta) == "unknown: the file does not say"


def test_spz_flag(tmp_path):
    s = random_params(8, seed=1)
    (tmp_path / "a.spz").write_bytes(encode_spz(s, 3, antialiased=True))
    (tmp_path / "b.spz").write_bytes(encode_spz(s, 3, antialiased=False))
    assert trained(gb.load(tmp_path / "a.spz")) == (ANTIALIASED, "spz flag", None)
    assert describe(gb.load(tmp_path / "a.spz").meta) == "antialiased: spz flag"
    assert trained(gb.load(tmp_path / "b.spz"))[0] == UNKNOWN  # a clear flag says nothing


@pytest.mark.parametrize("flag", [True, False])
def test_sog_antialias_field(tmp_path, flag):
    files = sog_files(random_params(8, seed=2))
    meta = json.loads(files["meta.json"])
    meta["antialias"] = flag
    files["meta.json"] = json.dumps(meta).encode()
    scene = gb.load(write_sog(files, tmp_path / "s.sog"))
    assert trained(scene)[:2] == ((ANTIALIASED, "sog antialias field") if flag else (UNKNOWN, "the file does not say"))


def test_filter_3d_column(tmp_path):
    assert trained(gb.load(write_ply(tmp_path / "s.ply", filter_3d=True))) == (MIP_3D, "filter_3D column", None)
    # Mip-Splatting trains with its 2D filter as well: an antialiased comment agrees
    agree = gb.load(write_ply(tmp_path / "t.ply", ["SplatRenderMode: mip"], filter_3d=True))
    assert trained(agree) == (MIP_3D, "filter_3D column", None)


def test_conflicts_follow_the_rule(tmp_path):
    data_wins = gb.load(write_ply(tmp_path / "a.ply", ["SplatRenderMode: default"], filter_3d=True))
    assert trained(data_wins)[:2] == (MIP_3D, "filter_3D column")
    assert trained(data_wins)[2] == (
        "3dgs: PLY comment 'SplatRenderMode: default' overruled by mip-splatting "
        "(3D filter): filter_3D column (the filter_3D column outranks a declaration)"
    )
    last_wins = gb.load(write_ply(tmp_path / "b.ply", ["SplatRenderMode: mip", "SplatRenderMode: default"]))
    assert trained(last_wins)[:2] == (THREEDGS, "PLY comment 'SplatRenderMode: default'")
    assert "the last declaration wins" in trained(last_wins)[2]
    assert describe(last_wins.meta).startswith("3dgs: PLY comment 'SplatRenderMode: default' (conflict: antialiased")


def test_convert_writes_the_comment(tmp_path, capsys):
    s = random_params(8, seed=4)
    (tmp_path / "a.spz").write_bytes(encode_spz(s, 3, antialiased=True))
    assert main(["convert", str(tmp_path / "a.spz"), str(tmp_path / "a.ply")]) == 0
    head = (tmp_path / "a.ply").read_bytes()[:400]
    assert b"comment SplatRenderMode: mip\n" in head
    assert trained(gb.load(tmp_path / "a.ply")) == (ANTIALIASED, "PLY comment 'SplatRenderMode: mip'", None)
    (tmp_path / "b.spz").write_bytes(encode_spz(s, 3))
    assert main(["convert", str(tmp_path / "b.spz"), str(tmp_path / "b.ply")]) == 0
    assert b"comment" not in (tmp_path / "b.ply").read_bytes()[:400]  # unknown: nothing claimed


def test_info_says_where_it_came_from(tmp_path, capsys):
    s = random_params(8, seed=5)
    (tmp_path / "a.spz").write_bytes(encode_spz(s, 3, antialiased=True))
    capsys.readouterr()
    assert main(["info", str(tmp_path / "a.spz"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["trained_as"] == "antialiased: spz flag"


def test_an_option_against_the_mode_the_file_says_names_the_file(tmp_path, capsys):
    """render of an antialiased file with --sh-degree 1 and no --mode said "mode 'preset:gsplat-antialiased' sets sh
    degree 3; sh degree 1 disagrees (give one of them)": a mode the user never gave. The line says where it came
    from and that --mode overrides it."""
    path = write_ply(tmp_path / "s.ply", ["SplatRenderMode: mip"])
    out = str(tmp_path / "o.png")
    assert main(["render", str(path), "--sh-degree", "1", "--width", "8", "--height", "8", "--out", out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"{path} says it was trained as antialiased" in err and "unless --mode says otherwise" in err
    assert (
        main(
            [
                "render",
                str(path),
                "--mode",
                "scalar",
                "--sh-degree",
                "1",
                "--width",
                "8",
                "--height",
                "8",
                "--out",
                out,
                "--backend",
                "cpu",
            ]
        )
        == 0
    )
