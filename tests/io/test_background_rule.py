"""One rule for the background a scene renders on against its photos (`choose_background`), the viewer's and eval's:
on a capture photographed against a grey backdrop, eval scores the renders on that grey by default (as the viewer
shows them), says so in its table and JSON, and a given colour still wins."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from dataset_builders import shots, write_colmap

import gbviewer as gb
from gbviewer import cli
from gbviewer import eval as ev
from gbviewer.io.datasets import load_dataset, read_photo
from gbviewer.io.datasets.backdrop import DEFAULT, GIVEN, PHOTOS, Backdrop, choose_background, estimate_backdrop
from gbviewer.outputs.metrics import psnr
from gbviewer.render import RenderSettings

pytest.importorskip("skimage")
GREY = 0.45


@pytest.fixture(scope="module")
def grey_capture(bundled_scene, tmp_path_factory):
    """A COLMAP capture of opaque photos: the scene's dense renders over a grey backdrop."""
    root = tmp_path_factory.mktemp("grey")
    views = [replace(s, rgb=s.rgb + (1.0 - s.alpha[..., None]) * np.float32(GREY)) for s in shots(bundled_scene, 3)]
    return write_colmap(root, views)


def test_the_rule():
    opaque, rgba = Backdrop((0.5, 0.5, 0.5), True, 8), Backdrop((0.5, 0.5, 0.5), False, 8)
    assert choose_background(None, opaque) == choose_background(None, opaque)
    assert (choose_background(None, opaque).colour, choose_background(None, opaque).source) == ((0.5,) * 3, PHOTOS)
    assert choose_background(None, rgba).source == DEFAULT and choose_background(None, rgba).colour == (0.0,) * 3
    assert choose_background(None, None).source == DEFAULT
    assert (
        choose_background((1, 1, 1), opaque).colour == (1.0,) * 3
        and choose_background((1, 1, 1), opaque).source == GIVEN
    )


def test_eval_scores_on_the_photos_backdrop_and_says_so(grey_capture, bundled_scene, tmp_path, capsys):
    settings = RenderSettings.parse_list("scalar")
    out = tmp_path / "e.json"
    assert (
        cli.main(
            [
                "eval",
                str(gb.DEFAULT_SCENE),
                "--data",
                str(grey_capture),
                "--modes",
                "scalar",
                "--rates",
                "1",
                "--split",
                "all",
                "--backend",
                "cpu",
                "--cache",
                str(tmp_path / "c"),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    used = doc["scenes"][0]["background"]
    assert used["source"] == PHOTOS and used["rgb"] == pytest.approx([GREY] * 3, abs=2 / 255)  # 8-bit photos
    assert "background " + used["describe"] in " ".join(printed.split())
    views = load_dataset(grey_capture).views
    backdrop = estimate_backdrop(views)
    assert tuple(used["rgb"]) == backdrop.colour  # the viewer's estimate, the same function
    scores = {v["name"]: v["results"][0]["psnr"] for v in doc["scenes"][0]["views"]}
    for view in views:  # the numbers of the backdrop's colour, computed directly
        img = gb.render(bundled_scene, view.camera, "scalar", background=backdrop.colour).rgb
        assert scores[view.name] == pytest.approx(psnr(img, read_photo(view.image)), abs=1e-4)
        black = gb.render(bundled_scene, view.camera, "scalar").rgb
        assert scores[view.name] > psnr(black, read_photo(view.image)) + 6  # what eval used to report
    given = ev.run_eval(
        [(gb.DEFAULT_SCENE, grey_capture)],
        settings,
        [1.0],
        split="all",
        background=(0, 0, 0),
        backend="cpu",
        cache=tmp_path / "c",
    )
    assert given.scenes[0].background.source == GIVEN
    assert ev.to_json(given)["scenes"][0]["views"][0]["results"][0]["psnr"] < min(scores.values()) - 6


def test_compare_and_bench_report_their_background(tmp_path, capsys, bundled_scene):
    view = ["--orbit", "30,20,0", "--width", "64", "--height", "48", "--rates", "1", "--backend", "cpu"]
    assert (
        cli.main(["compare", str(gb.DEFAULT_SCENE), *view, "--modes", "scalar", "--out", str(tmp_path / "a.png")]) == 0
    )
    assert "modes on background 0.00 0.00 0.00 (default: no photos)" in capsys.readouterr().out
    assert (
        cli.main(
            [
                "compare",
                str(gb.DEFAULT_SCENE),
                *view,
                "--modes",
                "scalar",
                "--background",
                "0.5,0.5,0.5",
                "--out",
                str(tmp_path / "b.png"),
            ]
        )
        == 0
    )
    assert "modes on background 0.50 0.50 0.50 (given)" in capsys.readouterr().out
    from gbviewer import bench

    doc = json.loads(bench.write_json(tmp_path / "b.json", [], []).read_text())
    assert doc["background"] == {
        "rgb": [0.0, 0.0, 0.0],
        "source": DEFAULT,
        "describe": "0.00 0.00 0.00 (default: no photos)",
    }
