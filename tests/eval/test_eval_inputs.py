"""`gbviewer eval`'s inputs, refused in one line before any work: SCENE:DATASET pairs, rates and modes (repeated or
empty items), existing outputs, a cache inside the dataset, a photo beyond the memory budget, a wrong Ray address."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from dataset_builders import H
from PIL import Image

import gbviewer as gb
from gbviewer import cli
from gbviewer import eval as ev
from gbviewer.cli.eval_args import scene_pairs
from gbviewer.eval import multiscale as gt_module
from gbviewer.eval.memory import view_bytes
from gbviewer.io.datasets import load_dataset
from gbviewer.model.camera import parse_rates
from gbviewer.render import RenderSettings


def test_scene_pairs(tmp_path):
    (tmp_path / "scenes").mkdir()
    for name in ("b.ply", "a.spz", "notes.txt"):
        (tmp_path / "scenes" / name).write_bytes(b"")
    assert scene_pairs([str(tmp_path / "scenes")], tmp_path / "data") == [
        (tmp_path / "scenes" / "a.spz", tmp_path / "data" / "a"),
        (tmp_path / "scenes" / "b.ply", tmp_path / "data" / "b"),
    ]
    assert scene_pairs(["x.ply:/d/x", "z.ply:/d/z"], None) == [
        (Path("x.ply"), Path("/d/x")),
        (Path("z.ply"), Path("/d/z")),
    ]
    assert scene_pairs(["y.ply"], Path("/d/y")) == [(Path("y.ply"), Path("/d/y"))]
    with pytest.raises(gb.GBViewerError, match=r"^x.ply:/d/x: SCENE:DATASET names its dataset; --data /d/y too"):
        scene_pairs(["y.ply", "x.ply:/d/x"], Path("/d/y"))  # --data was silently ignored for x.ply
    with pytest.raises(gb.GBViewerError, match="give --data DATASET or y.ply:DATASET"):
        scene_pairs(["y.ply"], None)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--rates", "2"], "rate x2 is finer than the photos"),
        (["--rates", "1,0.3"], "is not 1/k for an integer k"),
        (["--split", "test", "--data", "nowhere"], "no such dataset folder"),
    ],
)
def test_cli_errors_are_one_line(args, message, capsys, tmp_path):
    status = cli.main(["eval", str(gb.DEFAULT_SCENE), "--data", str(tmp_path), *args, "--cache", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and message in err, err


def test_existing_outputs_are_refused_before_the_work(tmp_path, capsys, monkeypatch):
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "fruit_drops_minimal.png").write_bytes(b"mine")
    monkeypatch.setattr(ev, "run_eval", lambda *a, **k: pytest.fail("evaluated despite an existing output"))
    status = cli.main(
        ["eval", str(gb.DEFAULT_SCENE), "--data", str(tmp_path / "data"), "--plots", str(tmp_path / "p")]
    )  # (a file inside the dataset folder would be refused as an input)
    err = capsys.readouterr().err
    assert status == 2 and err.splitlines() == [
        f"gbviewer: error: {tmp_path / 'p' / 'fruit_drops_minimal.png'}: exists; pass --force to overwrite"
    ]
    assert (tmp_path / "p" / "fruit_drops_minimal.png").read_bytes() == b"mine"


def test_a_huge_photo_is_refused_before_the_work(blender, capture, tmp_path, capsys, monkeypatch):
    """The view's whole need (photo decode, ground truths, SSIM, renders) is estimated from the camera before any
    photo is decoded: an 8000x6000 photo needs far more than its render buffers (it used > 9 GB unchecked), and a
    budget below a small view's need refuses it in one line naming the photo, the budget and how to raise it."""
    view = load_dataset(blender).views[0]
    huge = type(view)(view.name, dataclasses.replace(view.camera, width=8000, height=6000), view.image, view.split)
    scalar = RenderSettings.parse_list("scalar")
    assert view_bytes(huge, scalar, [1.0]) > 9 << 30 > view_bytes(view, scalar, [1.0, 1 / 2]) * 1000
    assert view_bytes(view, RenderSettings.parse_list("scalar,scalar:3"), [1.0]) > view_bytes(view, scalar, [1.0])
    monkeypatch.setattr(gt_module, "read_photo", lambda path: pytest.fail("decoded a photo beyond the budget"))
    monkeypatch.setenv("GBVIEWER_MEMORY_BUDGET", "1M")
    for data, hint in ((blender, False), (capture, True)):
        status = cli.main(
            [
                "eval",
                str(gb.DEFAULT_SCENE),
                "--data",
                str(data),
                "--rates",
                "1",
                "--modes",
                "scalar",
                "--cache",
                str(tmp_path / "c"),
                "--json",
                str(tmp_path / "out.json"),
            ]
        )
        err = capsys.readouterr().err
        assert status == 2 and len(err.splitlines()) == 1, err
        assert f"x{H} photo needs about" in err and "0.000977 GiB budget (GBVIEWER_MEMORY_BUDGET)" in err, err
        assert ".png:" in err and ("--images images_4" in err) == hint, err
        assert not (tmp_path / "out.json").exists()


@pytest.mark.parametrize(
    "address, message",
    [
        ("256.1.1.1:1", "256.1.1.1 is not a valid IPv4 address"),
        ("127.0.0.1:1", "nothing accepts a connection at 127.0.0.1 port 1 within 5 s"),
        ("ray://127.0.0.1:1", "nothing accepts a connection at 127.0.0.1 port 1"),
        ("127.0.0.1", "expected host:port"),
        ("127.0.0.1:0", "expected host:port (port 1..65535)"),
        ("127.0.0.1:http", "expected host:port"),
    ],
)
def test_a_wrong_ray_address_is_one_line_before_ray(address, message, capsys, tmp_path, monkeypatch):
    """The address is checked (syntax, the host, a TCP connect with a 5 s timeout) before the datasets and before
    ray.init, which retried for minutes with 20 lines of warnings. (.invalid never resolves: RFC 6761.)"""
    monkeypatch.setattr("gbviewer.eval.cluster.require", lambda *a, **k: pytest.fail("ray.init with a bad address"))
    status = cli.main(
        [
            "eval",
            str(gb.DEFAULT_SCENE),
            "--data",
            str(tmp_path / "none"),
            "--ray",
            address,
            "--cache",
            str(tmp_path / "c"),
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and err.startswith(f"gbviewer: error: --ray {address}: "), err
    assert message in err, err


def test_repeated_or_empty_rates_and_modes_are_refused():
    """A repeated rate (1/2 and 0.5 are one) would count twice in the average, a repeated mode (SCALAR, scalar:1
    and supersample:1 are scalar) is the same work twice; an empty item is a typo."""
    assert parse_rates("1, 1/2,1/8") == [1.0, 0.5, 0.125]
    assert [s.spec for s in RenderSettings.parse_list("scalar,scalar:2,supersample:3")] == [
        "scalar",
        "scalar:2",
        "scalar:3",
    ]
    for text, message in (
        ("1,1/2,1/2", "'1/2' repeats '1/2'"),
        ("1,0.5,1/2", "'1/2' repeats '0.5'"),
        ("1,,1/2", "empty item in '1,,1/2'"),
        ("1,", "empty item"),
        ("", "empty item"),
    ):
        with pytest.raises(gb.GBViewerError, match=f"^rates: {message}"):
            parse_rates(text)
    for text, message in (
        ("scalar,scalar,SCALAR", "'scalar' repeats 'scalar'"),
        ("SCALAR,scalar:1", "'scalar:1' repeats 'SCALAR'"),
        ("supersample:2,scalar:2", "'scalar:2' repeats 'supersample:2'"),
        ("scalar,", "empty item in 'scalar,'"),
        (" ", "empty item"),
    ):
        with pytest.raises(gb.GBViewerError, match=f"^--modes: {message}"):
            RenderSettings.parse_list(text)


@pytest.mark.parametrize(
    "command, args, message",
    [
        ("eval", ["--data", "nowhere", "--rates", "1,1/2,1/2"], "argument --rates: '1/2' repeats '1/2'"),
        ("eval", ["--data", "nowhere", "--rates", "1,,1/2"], "argument --rates: empty item in '1,,1/2'"),
        ("eval", ["--data", "nowhere", "--modes", "scalar,scalar,SCALAR"], "--modes: 'scalar' repeats 'scalar'"),
        ("eval", ["--data", "nowhere", "--modes", "scalar,"], "--modes: empty item in 'scalar,'"),
        ("trace", ["--pixel", "1,1", "--modes", "scalar,scalar"], "--modes: 'scalar' repeats 'scalar'"),
        ("bench", ["--modes", "mip,,scalar"], "--modes: empty item in 'mip,,scalar'"),
    ],
)
def test_repeated_or_empty_items_are_one_cli_line(command, args, message, capsys, tmp_path):
    status = cli.main([command, str(gb.DEFAULT_SCENE), *args])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and message in err, err


def test_a_cache_in_the_dataset_is_refused(blender, capture, tmp_path, capsys):
    """--cache the dataset folder, inside it, or (a cameras.json) in its photo folder: one line, nothing written.
    Beside a cameras.json (a 3DGS output folder) is not in the dataset."""
    cameras = tmp_path / "set" / "cameras.json"
    cameras.parent.mkdir()
    cameras.write_text("[]")
    for data, cache in (
        (blender, blender),
        (blender, blender / "sub" / "cache"),
        (capture, capture / "images"),
        (cameras, cameras.parent / "images" / "c"),
    ):
        before = sorted(data.parent.rglob("*"))
        status = cli.main(
            ["eval", f"{gb.DEFAULT_SCENE}:{data}", "--rates", "1,1/2", "--modes", "scalar", "--cache", str(cache)]
        )
        err = capsys.readouterr().err
        assert status == 2 and len(err.splitlines()) == 1, err
        assert f"--cache {cache}: is inside the dataset {data if data.is_dir() else data.parent / 'images'}" in err
        assert sorted(data.parent.rglob("*")) == before


def test_an_8000x6000_photo_is_refused_under_an_8g_budget(tmp_path, capsys, monkeypatch):
    """The tester's case: an all-zero 8000x6000 PNG (grey, tens of KB) took > 9 GB and > 70 s; now refused in
    one line before it is decoded, naming the photo, its size, the estimate and the budget."""
    (tmp_path / "images").mkdir()
    Image.new("L", (8000, 6000)).save(tmp_path / "images" / "a.png", compress_level=1)
    cams = [
        {
            "id": 0,
            "img_name": "a",
            "width": 800,
            "height": 600,
            "position": [0, 0, 0],
            "rotation": np.eye(3).tolist(),
            "fx": 700.0,
            "fy": 700.0,
        }
    ]
    (tmp_path / "cameras.json").write_text(json.dumps(cams))
    monkeypatch.setattr(gt_module, "read_photo", lambda path: pytest.fail("decoded the photo"))
    monkeypatch.setenv("GBVIEWER_MEMORY_BUDGET", "8G")
    status = cli.main(
        [
            "eval",
            str(gb.DEFAULT_SCENE),
            "--data",
            str(tmp_path / "cameras.json"),
            "--rates",
            "1",
            "--modes",
            "scalar",
            "--split",
            "all",
            "--cache",
            str(tmp_path / "c"),
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1, err
    assert f"{tmp_path / 'images' / 'a.png'}: the 8000x6000 photo needs about 1" in err, err
    assert "more than the 8 GiB budget (GBVIEWER_MEMORY_BUDGET); set GBVIEWER_MEMORY_BUDGET" in err
    assert "--images images_4" in err
