"""`gbviewer eval`: alpha-aware box-downsampled ground truth (hand-computed cases, the darkening a straight average
causes), its disk cache, the numbers against metrics computed directly, and the same JSON from one process, a
process pool and a local Ray instance. The inputs it refuses: test_eval_inputs.py."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from dataset_builders import H, W, save_rgba, shots, write_blender
from helpers import skip_or_fail
from PIL import Image

import gbviewer as gb
from gbviewer import eval as ev
from gbviewer.eval import multiscale as gt_module
from gbviewer.eval import report as report_module
from gbviewer.io.datasets import load_dataset, read_photo
from gbviewer.outputs.metrics import box_downsample, composite, premultiplied_box_downsample, psnr, ssim
from gbviewer.render import RenderSettings

PACKAGE_ROOT = Path(gb.__file__).resolve().parents[1]
WHITE = (1.0, 1.0, 1.0)


def test_premultiplied_box_downsample_hand_cases():
    """One opaque red pixel among three transparent ones (colour 0): a quarter of red over the background, and
    a half-transparent white beside an opaque blue: colours weighted by alpha."""
    rgba = np.zeros((2, 2, 4), np.float32)
    rgba[0, 0] = (1, 0, 0, 1)
    down = premultiplied_box_downsample(rgba, 2)
    assert down.shape == (1, 1, 4) and np.allclose(down[0, 0], (0.25, 0, 0, 0.25))
    assert np.allclose(composite(down, WHITE)[0, 0], (1.0, 0.75, 0.75))
    assert np.allclose(composite(down, (0, 0, 0))[0, 0], (0.25, 0, 0))
    rgba = np.array([[[1, 1, 1, 0.5], [0, 0, 1, 1]]], np.float32).repeat(2, axis=0)
    assert np.allclose(composite(premultiplied_box_downsample(rgba, 2), (0, 0, 0))[0, 0], (0.25, 0.25, 0.75))
    rgb = np.arange(5 * 7 * 3, dtype=np.float32).reshape(5, 7, 3)  # RGB: a plain box average, ragged edge cropped
    assert np.array_equal(premultiplied_box_downsample(rgb, 2), box_downsample(rgb, 2))
    assert premultiplied_box_downsample(rgb, 2).shape == (2, 3, 3)


def test_straight_average_darkens_an_rgba_edge():
    """A white object's edge inside 4x4 blocks, over white: the alpha-weighted downsample stays white (it is the
    average of the composited photo); averaging straight colour and alpha apart, as the original multi-scale
    Blender set did, turns the edge grey (transparent pixels carry colour 0)."""
    rgba = np.zeros((8, 8, 4), np.float32)
    rgba[:, :3] = (1, 1, 1, 1)  # columns 0..2 opaque white, the rest transparent black
    ours = composite(premultiplied_box_downsample(rgba, 4), WHITE)
    straight = box_downsample(rgba, 4)
    naive = straight[..., :3] * straight[..., 3:] + (1 - straight[..., 3:]) * 1.0
    assert np.allclose(ours, 1.0)
    assert np.allclose(ours, box_downsample(composite(rgba, WHITE), 4))
    assert np.allclose(naive[:, 0], 0.75 * 0.75 + 0.25) and np.allclose(naive[:, 1], 1.0)  # 0.8125: darker


def direct_truth(path: Path, k: int, background) -> np.ndarray:
    """The ground truth computed apart from gbviewer: the 8-bit photo in float64, composited, k x k means."""
    px = np.asarray(Image.open(path), np.float64) / 255
    rgb = px[..., :3] * px[..., 3:] + (1 - px[..., 3:]) * np.asarray(background) if px.shape[-1] == 4 else px
    h, w = rgb.shape[0] // k, rgb.shape[1] // k
    return rgb[: h * k, : w * k].reshape(h, k, w, k, 3).mean(axis=(1, 3))


def test_ground_truth_and_its_camera(blender):
    view = load_dataset(blender).split("test")[0]
    for rate, k in ((1, 1), (1 / 2, 2), (1 / 8, 8)):
        truth = ev.ground_truth(view, rate, WHITE)
        cam = ev.camera_for_rate(view.camera, rate)
        assert truth.dtype == np.float32 and truth.shape == (H // k, W // k, 3) == (cam.height, cam.width, 3)
        assert np.abs(truth - direct_truth(view.image, k, WHITE)).max() < 1e-6
        assert (cam.fx, cam.cx) == pytest.approx((view.camera.fx / k, view.camera.cx / k), rel=1e-12)
    for rate, why in ((2, "finer than the photos"), (0.3, "not 1/k"), (1 / 128, "smaller than 128 pixels")):
        with pytest.raises(gb.GBViewerError, match=why):
            ev.ground_truth(view, rate)


def test_cache_is_keyed_by_the_photo_and_stays_out_of_the_dataset(tmp_path, bundled_scene, monkeypatch):
    data = write_blender(tmp_path / "data", shots(bundled_scene, n=1, vary=False), test=(0,))
    before = sorted(p.relative_to(data) for p in data.rglob("*"))
    view, cache = load_dataset(data).views[0], tmp_path / "cache"
    first = ev.ground_truths(view, [1 / 2, 1 / 4], WHITE, cache)
    assert len(list(cache.iterdir())) == 2 and sorted(p.relative_to(data) for p in data.rglob("*")) == before
    expected = composite(premultiplied_box_downsample(read_photo(view.image), 2), (0.0, 0.0, 0.0))
    monkeypatch.setattr(gt_module, "read_photo", lambda path: pytest.fail("decoded a cached photo"))
    again = ev.ground_truths(view, [1 / 2, 1 / 4], (0.0, 0.0, 0.0), cache)  # the background is applied after
    assert np.array_equal(again[0], expected) and not np.array_equal(again[0], first[0])
    monkeypatch.undo()
    save_rgba(view.image, np.zeros((H, W, 3)), np.ones((H, W)))  # another photo at the same path: a new key
    assert np.array_equal(ev.ground_truths(view, [1 / 2], WHITE, cache)[0], np.zeros((H // 2, W // 2, 3)))
    assert not np.array_equal(first[0], np.zeros((H // 2, W // 2, 3)))
    for entry in cache.iterdir():
        entry.write_bytes(b"garbage")  # a damaged entry is recomputed, not an error
    assert np.array_equal(ev.ground_truths(view, [1 / 2], WHITE, cache)[0], np.zeros((H // 2, W // 2, 3)))


def test_eval_numbers_are_the_metrics_computed_directly(blender, bundled_scene, tmp_path):
    settings = RenderSettings.parse_list("scalar,gaussian_blending,scalar:2")
    rates = [1.0, 1 / 2, 1 / 8]
    result = ev.run_eval(
        [(gb.DEFAULT_SCENE, blender)], settings, rates, background=WHITE, backend="cpu", cache=tmp_path / "cache"
    )
    doc = ev.to_json(result)
    scene = doc["scenes"][0]
    assert [v["name"] for v in scene["views"]] == ["test/v00", "test/v08"]
    for v in scene["views"]:
        view = next(x for x in load_dataset(blender).views if x.name == v["name"])
        for r in v["results"]:
            s = RenderSettings.parse(r["mode"], background=WHITE)
            k = round(1 / r["rate"])
            cam = gb.Camera(
                W // k,
                H // k,
                view.camera.fx / k,
                view.camera.fy / k,
                view.camera.cx / k,
                view.camera.cy / k,
                view.camera.R,
                view.camera.t,
            )
            img = gb.get_renderer(bundled_scene).render(cam, s).rgb
            truth = direct_truth(view.image, k, WHITE)
            assert r["psnr"] == pytest.approx(psnr(img, truth), abs=1e-4)
            assert r["ssim"] == pytest.approx(ssim(img, truth), abs=1e-6)
    for row in scene["table"]:
        per_view = [
            x["psnr"]
            for v in scene["views"]
            for x in v["results"]
            if (x["mode"], x["rate"]) == (row["mode"], row["rate"])
        ]
        assert row["psnr"] == pytest.approx(np.mean(per_view), rel=1e-12)
    avg = {a["mode"]: a["psnr"] for a in scene["average"]}
    assert avg["scalar"] == pytest.approx(np.mean([r["psnr"] for r in scene["table"] if r["mode"] == "scalar"]))
    assert doc["mean"]["table"] == scene["table"]  # one scene: its own mean


def test_several_scenes_give_a_table_each_and_their_mean(blender, capture, tmp_path, capsys):
    result = ev.run_eval(
        [(gb.DEFAULT_SCENE, capture), (gb.DEFAULT_SCENE, blender)],
        RenderSettings.parse_list("scalar"),
        [1.0, 1 / 4],
        backend="cpu",
        cache=tmp_path / "c",
    )
    doc = ev.to_json(result)
    for i, row in enumerate(doc["mean"]["table"]):
        assert row["psnr"] == pytest.approx(
            (doc["scenes"][0]["table"][i]["psnr"] + doc["scenes"][1]["table"][i]["psnr"]) / 2
        )
    ev.print_tables(result)
    out = capsys.readouterr().out
    assert out.count("PSNR x1/4") == 3 and "Mean over 2 scenes" in out
    paths = ev.write_plots(tmp_path / "plots", result)
    assert [p.name for p in paths] == [
        f"fruit_drops_minimal_vs_{capture.name}.png",
        f"fruit_drops_minimal_vs_{blender.name}.png",
        "mean.png",
    ]
    assert all(p.is_file() for p in paths)


NEW_MODES = (
    "scalar,mip,analytic,gaussian_blending,scalar:2,stochastic,stochastic:2,stochastic_popfree,eval3d,"
    "stopthepop,stopthepop:0,preset:spark-stochastic"
)


def test_every_mode_has_its_rows_and_its_own_line(blender, tmp_path, monkeypatch):
    """The newer modes are evaluated under their own specs (stopthepop's queue, a stochastic preset) and each of
    more modes than matplotlib has cycle colours is drawn in a line no other mode shares."""
    settings = RenderSettings.parse_list(NEW_MODES, background=WHITE)
    result = ev.run_eval(
        [(gb.DEFAULT_SCENE, blender)], settings, [1.0, 1 / 8], background=WHITE, backend="cpu", cache=tmp_path / "cache"
    )
    doc = ev.to_json(result)
    assert doc["modes"] == NEW_MODES.split(",")
    assert [(r["mode"], r["rate"]) for r in doc["scenes"][0]["table"]] == [
        (m, r) for m in NEW_MODES.split(",") for r in (1.0, 1 / 8)
    ]
    assert all(r["psnr"] is not None for r in doc["scenes"][0]["table"])
    figures = []
    monkeypatch.setattr(report_module, "save_figure", lambda fig, path, force: figures.append(fig))
    ev.write_plots(tmp_path / "plots", result)
    for ax in figures[0].axes:
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == NEW_MODES.split(",")
        styles = {(line.get_color(), line.get_marker(), line.get_linestyle()) for line in lines}
        assert len(styles) == len(lines)


def run_cli(args: list[str], cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(PACKAGE_ROOT), "XDG_CACHE_HOME": str(cwd / "xdg"), **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "gbviewer", "eval", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )


def numbers(path: Path) -> dict:
    """The JSON without what depends on the run: times, the machine, how it ran."""

    def strip(d):
        if isinstance(d, dict):
            return {k: strip(v) for k, v in d.items() if k not in ("render_ms", "elapsed_s", "machine", "runner")}
        return [strip(v) for v in d] if isinstance(d, list) else d

    return strip(json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(f"{c} in the JSON")))


ARGS = ["--modes", "scalar,gaussian_blending", "--rates", "1,1/2,1/8", "--backend", "cpu", "--split", "all"]


def test_workers_2_give_the_same_json_as_1(capture, tmp_path):
    """A process pool gives the numbers of one process, in the same order; plots and the table are written."""
    one = run_cli(
        [str(gb.DEFAULT_SCENE), "--data", str(capture), *ARGS, "--json", "one.json", "--plots", "p"], tmp_path
    )
    assert one.returncode == 0, one.stderr
    assert "gaussian_blending" in one.stdout and "PSNR x1/8" in one.stdout and "9 views" in one.stdout
    assert (tmp_path / "p" / "fruit_drops_minimal.png").is_file()
    assert list((tmp_path / "xdg" / "gbviewer" / "ground_truth").iterdir())  # the default cache: XDG_CACHE_HOME
    two = run_cli([f"{gb.DEFAULT_SCENE}:{capture}", *ARGS, "--json", "two.json", "--workers", "2"], tmp_path)
    assert two.returncode == 0, two.stderr
    assert "2 workers" in two.stdout
    assert numbers(tmp_path / "one.json") == numbers(tmp_path / "two.json")


@pytest.mark.slow
def test_ray_local_gives_the_same_json(capture, tmp_path):
    """`--ray local`: the same tasks as Ray tasks on a Ray instance started for the run (about 20 s on 2 cores)."""
    try:
        import ray  # noqa: F401
    except ImportError:
        skip_or_fail("ray is not installed (pip install 'gbviewer[ray]')")
    args = [str(gb.DEFAULT_SCENE), "--data", str(capture), *ARGS, "--split", "test", "--cache", "c"]
    local = run_cli([*args, "--json", "local.json"], tmp_path)
    assert local.returncode == 0, local.stderr
    on_ray = run_cli([*args, "--json", "ray.json", "--ray", "local"], tmp_path, {"RAY_USAGE_STATS_ENABLED": "0"})
    assert on_ray.returncode == 0, on_ray.stderr[-3000:]
    assert "ray local" in on_ray.stdout and "Token authentication" not in on_ray.stderr
    assert numbers(tmp_path / "local.json") == numbers(tmp_path / "ray.json")


def test_auto_backend_follows_the_one_rule_and_gpu_requests_follow_capabilities():
    """eval's auto is `choose_backend`'s pick (no policy of its own); Ray asks for GPUs by capability, not name."""
    from gbviewer.eval.cluster import renders_on_device
    from gbviewer.eval.tasks import pick_backend
    from gbviewer.render import BACKENDS, choose_backend

    assert pick_backend("auto") == choose_backend().name
    assert pick_backend("cpu") == "cpu"
    assert renders_on_device("auto")
    for name, cls in BACKENDS.items():
        assert renders_on_device(name) == (not cls.capabilities.host)
