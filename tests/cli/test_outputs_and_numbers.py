"""Outputs never destroy inputs (same file through a symlink, a hard link or a relative path; refused with or
without --force), writers follow the overwrite rule (demo), colliding outputs of one run are refused before the
work, cameras are checked after every transformation (--scale, --rates), JSON is strict (non-finite numbers are
null) and a frame beyond the memory budget is refused in one line: each as one line on stderr, exit status 2,
nothing written and nothing lost."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from helpers import random_scene

import gbviewer as gb
from gbviewer import cli
from gbviewer.core.errors import RenderError
from gbviewer.io import write_inria_ply
from gbviewer.render import RenderSettings
from gbviewer.render.budget import BUDGET_ENV, check_frame_memory, memory_budget


@pytest.fixture()
def work(tmp_path, monkeypatch):
    """tmp_path as the current folder, with scene.ply (20 splats in front of the origin looking down +z) and
    cameras.json (fx = fy = 2e-38: a normal float32 at x1, below the smallest one at x1/2)."""
    monkeypatch.chdir(tmp_path)
    write_inria_ply(random_scene(20, seed=3), tmp_path / "scene.ply")
    cams = [
        {
            "id": 0,
            "img_name": "a",
            "width": 32,
            "height": 24,
            "position": [0, 0, 0],
            "rotation": np.eye(3).tolist(),
            "fx": 2e-38,
            "fy": 2e-38,
        }
    ]
    (tmp_path / "cameras.json").write_text(json.dumps(cams))
    return tmp_path


def snapshot(folder):
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def refused(argv, capsys, *expect) -> str:
    status = cli.main(argv)
    out, err = capsys.readouterr()
    assert status == 2 and len(err.splitlines()) == 1 and err.startswith("gbviewer: error: "), err
    assert all(e in err for e in expect), err
    return err


@pytest.mark.parametrize("force", [[], ["--force"]], ids=["plain", "force"])
@pytest.mark.parametrize("kind", ["same", "relative", "symlink", "hardlink"])
def test_an_output_that_is_an_input_is_refused(work, capsys, kind, force):
    (work / "sub").mkdir()
    out = {"same": "scene.ply", "relative": "sub/../scene.ply", "symlink": "link.ply", "hardlink": "hard.ply"}[kind]
    if kind == "symlink":
        (work / "link.ply").symlink_to(work / "scene.ply")
    if kind == "hardlink":
        os.link(work / "scene.ply", work / "hard.ply")
    before = snapshot(work)
    refused(["convert", "scene.ply", out, *force], capsys, "is the input scene.ply", "refused even with --force")
    assert snapshot(work) == before


@pytest.mark.parametrize(
    "argv",
    [
        ["trace", "scene.ply", "--pixel", "1,1", "--cameras", "cameras.json", "--json", "cameras.json", "--force"],
        ["compare", "scene.ply", "--out", "scene.ply", "--force"],
        ["video", "scene.ply", "--path", "keys.json", "--out", "keys.json", "--force"],
        ["bench", "scene.ply", "--json", "scene.ply", "--force"],
    ],
    ids=["trace", "compare", "video", "bench"],
)
def test_every_writer_refuses_its_inputs(work, capsys, argv):
    (work / "keys.json").write_text("[]")
    before = snapshot(work)
    refused(argv, capsys, "the input")
    assert snapshot(work) == before


def test_eval_output_inside_the_dataset_folder_is_refused(work, capsys):
    (work / "data").mkdir()
    (work / "data" / "transforms_test.json").write_text("{}")
    before = snapshot(work)
    refused(
        ["eval", "scene.ply:data", "--json", "data/transforms_test.json", "--force"],
        capsys,
        "lies inside the input data",
    )
    assert snapshot(work) == before


def test_demo_keeps_existing_files_without_force(work, capsys):
    (work / "out").mkdir()
    (work / "out" / "zoom.mp4").write_bytes(b"earlier video")
    before = snapshot(work)
    refused(["demo", "scene.ply", "--out", "out"], capsys, "zoom.mp4: exists; pass --force")
    assert snapshot(work) == before


@pytest.mark.parametrize(
    "argv",
    [
        ["eval", "a/s.ply:a/data", "b/s.ply:b/data", "--plots", "plots"],
        ["bench", "a/s.ply", "b/s.ply", "--plots", "plots"],
    ],
    ids=["eval", "bench"],
)
def test_outputs_colliding_within_one_run_are_refused_before_the_work(work, capsys, argv):
    for d in ("a", "b"):
        (work / d).mkdir()
        (work / d / "s.ply").write_bytes((work / "scene.ply").read_bytes())
    refused(argv, capsys, "s", "two outputs would be written to this one file")
    assert not (work / "plots").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["render", "scene.ply", "--cameras", "cameras.json", "--scale", "1/2", "--out", "x.png", "--backend", "cpu"],
        ["trace", "scene.ply", "--cameras", "cameras.json", "--scale", "1/2", "--pixel", "1,1"],
        ["compare", "scene.ply", "--cameras", "cameras.json", "--rates", "1,1/2", "--out", "x.png", "--backend", "cpu"],
    ],
    ids=["render", "trace", "compare"],
)
def test_a_focal_that_underflows_at_the_rate_is_one_line(work, capsys, argv):
    refused(argv, capsys, "camera 'a': fx: expected >= 1.175e-38", "at sampling rate x1/2")
    assert not (work / "x.png").exists()


def test_eval_checks_the_cameras_at_every_rate_before_the_work(work, capsys):
    from PIL import Image

    (work / "images").mkdir()
    Image.new("RGB", (32, 24)).save(work / "images" / "a.png")
    refused(
        [
            "eval",
            "scene.ply:cameras.json",
            "--rates",
            "1,1/2",
            "--split",
            "all",
            "--json",
            "r.json",
            "--cache",
            "cache",
        ],
        capsys,
        "fx: expected >= 1.175e-38",
        "at sampling rate x1/2",
    )
    assert not (work / "r.json").exists()


def test_trace_json_is_strict_with_nulls_for_non_finite_numbers(work):
    """A trace whose numbers over- or underflowed (a far or tiny-focal camera) is written as strict JSON: null."""
    from dataclasses import replace

    from gbviewer.outputs.trace_report import write_traces

    cam = gb.Camera(32, 24, 30, 30, 16, 12, np.eye(3), np.zeros(3))
    trace = gb.trace_pixel(random_scene(20, seed=3), cam, 16, 12)
    sample = replace(trace.samples[0], transmittance=float("nan"), total=float("inf"))
    bad = replace(
        trace,
        color=(float("inf"), 0.5, float("-inf")),
        transmittance=float("nan"),
        samples=(sample, *trace.samples[1:]),
    )

    def strict(name: str) -> float:
        raise AssertionError(f"{name} in strict JSON")

    doc = json.loads(bad.to_json(), parse_constant=strict)
    assert doc["color"] == [None, 0.5, None] and doc["transmittance"] is None
    assert doc["samples"][0]["transmittance"] is None and doc["samples"][0]["total"] is None
    write_traces(work / "t.json", [bad], "scene.ply")
    assert json.loads((work / "t.json").read_text(), parse_constant=strict)["traces"] == [doc]


def test_a_frame_beyond_the_memory_budget_is_refused_before_allocating(work, capsys, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "100M")  # duplex renders whole frames only: refused
    refused(
        [
            "render",
            "scene.ply",
            "--width",
            "1024",
            "--height",
            "1024",
            "--mode",
            "duplex:8",
            "--out",
            "x.png",
            "--backend",
            "cpu",
        ],
        capsys,
        "needs at least 1.",
        f"0.0977 GiB budget ({BUDGET_ENV})",
        f"set {BUDGET_ENV}",
    )
    monkeypatch.setenv(BUDGET_ENV, "10M")  # the other modes render in parts, but not even the stitched image fits
    refused(
        [
            "render",
            "scene.ply",
            "--width",
            "1024",
            "--height",
            "1024",
            "--supersample",
            "8",
            "--out",
            "x.png",
            "--backend",
            "cpu",
        ],
        capsys,
        "parts need",
        f"0.00977 GiB budget ({BUDGET_ENV})",
        f"set {BUDGET_ENV}",
    )
    assert not (work / "x.png").exists()
    for bad in ("lots", "1e3", "   ", "0.1", "0K", "-1G", "1.5X", "1.5GG", "1,5G"):
        monkeypatch.setenv(BUDGET_ENV, bad)
        with pytest.raises(RenderError, match=f"{BUDGET_ENV}: expected bytes >= 1, as a decimal number") as exc:
            memory_budget()
        assert repr(bad) in str(exc.value) and "\n" not in str(exc.value)
    for good, value in (("1000", 1000), ("1.5G", 3 << 29), (" 2k ", 2048), (".5M", 1 << 19), ("3 T", 3 << 40)):
        monkeypatch.setenv(BUDGET_ENV, good)
        assert memory_budget() == (value, BUDGET_ENV)
    monkeypatch.setenv(BUDGET_ENV, "64G")
    check_frame_memory(gb.Camera(1024, 1024, 8, 8, 4, 4, np.eye(3), np.zeros(3)), RenderSettings(supersample=8), 20)
    monkeypatch.delenv(BUDGET_ENV)
    with pytest.raises(RenderError, match="available memory|address-space limit"):
        check_frame_memory(
            gb.Camera(16384, 16384, 8, 8, 4, 4, np.eye(3), np.zeros(3)), RenderSettings(supersample=8), 20
        )


@pytest.mark.parametrize(
    "name, expect",
    [
        ("a" * 296 + ".png", "--out aaaa"),
        ("a" * 246 + ".png", "file name of 250 bytes; expected at most 245"),
        ("d" * 256 + "/x.png", "folder name of 256 bytes; expected at most 255"),
    ],
)
def test_an_output_name_over_the_limit_is_one_line(work, capsys, name, expect):
    """Not the raw '[Errno 36] File name too long': the option and the limit (the temporary file must fit too)."""
    err = refused(["render", "scene.ply", "--out", name, "--backend", "cpu"], capsys, "--out ", expect)
    assert "Errno" not in err
    assert sorted(p.name for p in work.iterdir()) == ["cameras.json", "scene.ply"]
    ok = "a" * 241 + ".png"  # at the limit: it and its temporary file are written
    assert cli.main(["render", "scene.ply", "--out", ok, "--width", "8", "--height", "8", "--backend", "cpu"]) == 0
    assert (work / ok).is_file()


def test_memory_running_out_after_the_estimate_is_one_line(work, capsys, monkeypatch):
    def bad_alloc(*args, **kwargs):
        raise MemoryError("std::bad_alloc")

    monkeypatch.setattr(cli.render, "get_renderer", bad_alloc)
    refused(
        ["render", "scene.ply", "--out", "x.png", "--backend", "cpu"],
        capsys,
        f"out of memory (std::bad_alloc); render smaller, or see {BUDGET_ENV}",
    )
    assert not (work / "x.png").exists()
