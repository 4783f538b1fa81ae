"""Training datasets: COLMAP (binary, text, through pycolmap), Blender transforms and 3DGS cameras.json round-trip
their cameras exactly (a render through a loaded camera equals the render through the original), split as the
papers do, rescale intrinsics for resized photos, and refuse bad datasets in one line (exit status 2 from the
command line)."""

from __future__ import annotations

import shutil
import struct
import zlib
from dataclasses import replace

import numpy as np
import pytest
from dataset_builders import H, W, save_rgb, shots, write_blender, write_cameras_json, write_colmap

import gbviewer as gb
from gbviewer import cli
from gbviewer.core.errors import DatasetError
from gbviewer.io.datasets import colmap, load_dataset, read_photo

pytest.importorskip("pycolmap")


@pytest.fixture(scope="module")
def views(bundled_scene):
    return shots(bundled_scene)


@pytest.fixture(scope="module")
def centred(bundled_scene):
    return shots(bundled_scene, vary=False)


def assert_same_cameras(scene, loaded, originals, renders=True):
    """Intrinsics and size exactly, the pose to float64 rounding, and (for a few views) identical renders."""
    assert len(loaded) == len(originals)
    for view, cam in zip(loaded, originals):
        c = view.camera
        assert (c.width, c.height, c.fx, c.fy, c.cx, c.cy) == (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
        assert np.abs(c.R - cam.R).max() < 1e-15 and np.abs(c.t - cam.t).max() < 1e-15
    for view, cam in list(zip(loaded, originals))[: 3 if renders else 0]:
        for mode in ("scalar", "gaussian_blending"):
            assert np.array_equal(gb.render(scene, view.camera, mode).rgb, gb.render(scene, cam, mode).rgb)


@pytest.mark.parametrize("text", [False, True], ids=["binary", "text"])
def test_colmap_round_trip_and_every_8th_photo_is_a_test_view(tmp_path, bundled_scene, views, text):
    data = load_dataset(write_colmap(tmp_path, views, text=text))
    assert data.format == "colmap"
    assert [v.name for v in data.views] == [f"{s.name}.png" for s in views]
    assert [v.name for v in data.split("test")] == ["v00.png", "v08.png"]
    assert len(data.split("train")) == 7 and len(data.split("all")) == 9
    assert all(v.image == tmp_path / "images" / v.name for v in data.views)
    assert_same_cameras(bundled_scene, data.views, [s.camera for s in views], renders=not text)


def test_colmap_model_without_rigs_and_frames(tmp_path, bundled_scene, views):
    """COLMAP 3 models (most published captures) have no rigs.bin or frames.bin."""
    write_colmap(tmp_path, views)
    for name in ("rigs.bin", "frames.bin"):
        (tmp_path / "sparse" / "0" / name).unlink()
    assert_same_cameras(bundled_scene, load_dataset(tmp_path).views, [s.camera for s in views], renders=False)


def test_blender_round_trip_with_rgba_photos(tmp_path, bundled_scene, centred):
    data = load_dataset(write_blender(tmp_path, centred))
    assert data.format == "blender"
    assert [v.name for v in data.split("test")] == ["test/v00", "test/v08"]
    assert [v.name for v in data.split("train")] == [f"train/v0{i}" for i in range(1, 8)]
    by_name = {s.name: s.camera for s in centred}
    loaded = sorted(data.views, key=lambda v: v.name.split("/")[1])
    for view in loaded:  # camera_angle_x is a float round trip of the focal length
        cam = by_name[view.name.split("/")[1]]
        assert view.camera.fx == pytest.approx(cam.fx, rel=1e-14) and view.camera.fy == view.camera.fx
    fixed = [
        replace(v, camera=replace(v.camera, fx=by_name[v.name.split("/")[1]].fx, fy=by_name[v.name.split("/")[1]].fy))
        for v in loaded
    ]
    assert_same_cameras(bundled_scene, fixed, [s.camera for s in centred])
    assert np.array_equal(
        gb.render(bundled_scene, loaded[0].camera).rgb, gb.render(bundled_scene, centred[0].camera).rgb
    )
    assert read_photo(loaded[0].image).shape == (H, W, 4)


def test_cameras_json_with_photos(tmp_path, bundled_scene, centred):
    data = load_dataset(write_cameras_json(tmp_path, centred))
    assert data.format == "cameras.json"
    assert [v.name for v in data.split("test")] == ["v00", "v08"]
    assert read_photo(data.views[0].image).shape == (H, W, 3)
    assert_same_cameras(bundled_scene, data.views, [s.camera for s in centred])
    again = load_dataset(tmp_path / "cameras.json")
    assert [(v.name, v.image, v.split) for v in again.views] == [(v.name, v.image, v.split) for v in data.views]


def test_resized_photos_rescale_the_intrinsics(tmp_path, views):
    """images_2 of a full-size COLMAP model; a cameras.json of a smaller training size than its photos."""
    write_colmap(tmp_path, views)
    for s in views:
        save_rgb(tmp_path / "images_2" / f"{s.name}.png", s.rgb[::2, ::2])
    half = load_dataset(tmp_path, images="images_2")
    assert_same_cameras(None, half.views, [s.camera.with_size(W // 2, H // 2) for s in views], renders=False)
    assert all(v.image.parent.name == "images_2" for v in half.views)
    small = [replace(s, camera=s.camera.with_size(W // 2, H // 2)) for s in views]
    big = load_dataset(write_cameras_json(tmp_path / "gs", small))  # json at half size, photos at full size
    assert [(v.camera.width, v.camera.height) for v in big.views] == [(W, H)] * len(views)


def one_line(exc: pytest.ExceptionInfo, *parts: str) -> str:
    text = str(exc.value)
    assert "\n" not in text and all(p in text for p in parts), text
    return text


def test_missing_photos_and_other_aspect_ratio(tmp_path, views):
    write_colmap(tmp_path, views)
    (tmp_path / "images" / "v03.png").unlink()
    (tmp_path / "images" / "v05.png").unlink()
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, "2 of the 9 photos", "missing", "v03.png")
    save_rgb(tmp_path / "images" / "v03.png", views[3].rgb)
    save_rgb(tmp_path / "images" / "v05.png", views[5].rgb[:, :80])
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, "v05.png", "80x100", "integer downscale")
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path, images="images_8")
    one_line(exc, "images_8", "--images")
    bomb = tmp_path / "images" / "v05.png"  # a valid header claiming 13000 x 10000 pixels, and no pixel data
    ihdr = b"IHDR" + struct.pack(">IIBBBBB", 13000, 10000, 8, 2, 0, 0, 0)
    idat = b"IDAT" + b"\0" * 8
    bomb.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + struct.pack(">I", 13)
        + ihdr
        + struct.pack(">I", zlib.crc32(ihdr))
        + struct.pack(">I", 8)
        + idat
        + struct.pack(">I", zlib.crc32(idat))
    )
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, "v05.png", "claims 13000x10000 pixels in 53 bytes")


@pytest.mark.parametrize(
    "model, extra, accepted",
    [
        ("SIMPLE_RADIAL", (0.0,), True),
        ("OPENCV", (0.0,) * 4, True),
        ("SIMPLE_RADIAL", (0.01,), False),
        ("SIMPLE_RADIAL_FISHEYE", (0.0,), False),
        ("OPENCV_FISHEYE", (0.0,) * 4, False),
    ],
)
def test_camera_models(tmp_path, views, model, extra, accepted):
    write_colmap(tmp_path, views, model=model, extra=extra)
    if accepted:
        assert len(load_dataset(tmp_path).views) == 9
        return
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, f"camera model {model}", "not supported", "PINHOLE", str(tmp_path / "sparse" / "0"))


def test_empty_split(tmp_path, centred):
    write_blender(tmp_path, centred, test=())
    data = load_dataset(tmp_path)
    with pytest.raises(DatasetError) as exc:
        data.split("test")
    one_line(exc, str(tmp_path), "no test views")


def truncate_name(model):
    """images.bin cut inside the first image's name: pycolmap 4.2.1's reader loops forever on it."""
    path = model / "images.bin"
    path.write_bytes(path.read_bytes()[: 8 + 4 + 7 * 8 + 4 + 2])


@pytest.mark.parametrize(
    "damage, expect",
    [
        (lambda d: (d / "cameras.bin").write_bytes(b"not a camera file" * 3), "Camera model does not exist"),
        (
            lambda d: (d / "images.bin").write_bytes(struct.pack("<Q", 1) + b"\0" * 60 + struct.pack("<Q", 1 << 40)),
            "an image refers to camera 0, which the model's cameras file does not define",
        ),
        (truncate_name, "still reading after"),
        (lambda d: (d / "images.bin").unlink(), "images.bin missing"),
    ],
)
def test_unreadable_sparse_model(tmp_path, views, monkeypatch, damage, expect):
    write_colmap(tmp_path, views[:2])
    for name in ("rigs.bin", "frames.bin"):
        (tmp_path / "sparse" / "0" / name).unlink()
    damage(tmp_path / "sparse" / "0")
    monkeypatch.setattr(colmap, "BASE_SECONDS", 3.0)
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, str(tmp_path / "sparse" / "0"), expect)


@pytest.mark.parametrize(
    "text, expect",
    [
        ('{"frames": []}', "missing 'camera_angle_x'"),
        ('{"camera_angle_x": 0.7, "frames": [{"file_path": "./a"}]}', "frame 0: missing 'transform_matrix'"),
        ('{"camera_angle_x": 0.7, "frames": [{"file_path": "./a", "transform_matrix": [[1]]}]}', "a 4x4 matrix"),
        ('{"camera_angle_x": "wide", "frames": []}', "expected a number"),
        (
            '{"camera_angle_x": 0.7, "frames": [{"file_path": "./a", "transform_matrix": '
            "[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 1, 1]]}]}",
            "frame 0: 'transform_matrix': expected a bottom row",
        ),
    ],
)
def test_bad_transforms(tmp_path, text, expect):
    (tmp_path / "transforms_test.json").write_text(text)
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, "transforms_test.json", expect)


def test_not_a_dataset(tmp_path):
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path)
    one_line(exc, str(tmp_path), "not a dataset")
    with pytest.raises(DatasetError) as exc:
        load_dataset(tmp_path / "nowhere")
    one_line(exc, "no such dataset folder")


@pytest.mark.parametrize("kind", ["missing photo", "camera model", "empty split", "unreadable model"])
def test_cli_bad_dataset_is_one_line_exit_2(tmp_path, views, centred, capsys, kind):
    data = tmp_path / "data"
    if kind == "empty split":
        write_blender(data, centred, test=())
    elif kind == "camera model":
        write_colmap(data, views[:2], model="OPENCV_FISHEYE", extra=(0.0,) * 4)
    else:
        write_colmap(data, views[:2])
    if kind == "missing photo":
        shutil.rmtree(data / "images")
        (data / "images").mkdir()
    if kind == "unreadable model":
        (data / "sparse" / "0" / "cameras.bin").write_bytes(b"\xff" * 40)
    status = cli.main(["eval", str(gb.DEFAULT_SCENE), "--data", str(data), "--cache", str(tmp_path / "cache")])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("gbviewer: error: ") and str(data) in err, err


def test_no_display_view_checks_the_dataset(tmp_path, centred, capsys, monkeypatch):
    """Without a display `gbviewer SCENE --data D` falls back to demo: a bad D is still one line and exit 2 with
    nothing written; a good one is read and the fallback says it does not use its photos."""
    from gbviewer.cli import view

    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    demos = []
    monkeypatch.setattr(view, "cmd_demo", lambda args: demos.append(args.data) or 0)
    out_dir = tmp_path / "out"
    (tmp_path / "bad").mkdir()
    command = ["view", str(gb.DEFAULT_SCENE), "--out", str(out_dir), "--data"]
    assert cli.main([*command, str(tmp_path / "bad")]) == 2
    out, err = capsys.readouterr()
    assert len(err.splitlines()) == 1 and "not a dataset" in err and str(tmp_path / "bad") in err, err
    assert demos == [] and not out_dir.exists()
    good = write_blender(tmp_path / "good", centred)
    assert cli.main([*command, str(good)]) == 0
    assert demos == [good] and "does not use the dataset's photos" in capsys.readouterr().out
