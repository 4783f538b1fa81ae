"""Dataset errors that name the real problem, on hand-written COLMAP text models of 8x6 photos: duplicate image
names, an undefined camera, a zero quaternion, a non-finite pose, an over-long photo name, photos that are not PNG
or JPEG by content, decode budgets, SCENE:/:DATASET; and the COLMAP reader under an address-space limit below its
own. Each is one line (exit status 2 from the command line) and writes nothing."""

from __future__ import annotations

import io
import os
import resource
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from gbviewer import cli
from gbviewer.core.errors import DatasetError
from gbviewer.io.datasets import load_dataset, photos, read_photo

pycolmap = pytest.importorskip("pycolmap")

CAMERA = "1 PINHOLE 8 6 10 10 4 3\n"
POSE = "1 0 0 0 0 0 5"  # qw qx qy qz tx ty tz


def colmap_text(root, images: list[tuple[str, str, str]], photo_names=None, camera=CAMERA):
    """root/sparse/0 as text with one PINHOLE camera 1 and images (pose, camera id, name); 8x6 PNGs."""
    model = root / "sparse" / "0"
    model.mkdir(parents=True)
    (model / "cameras.txt").write_text(camera)
    (model / "images.txt").write_text(
        "".join(f"{k + 1} {pose} {cam} {name}\n\n" for k, (pose, cam, name) in enumerate(images))
    )
    (root / "images").mkdir()
    for name in photo_names if photo_names is not None else {n for _, _, n in images}:
        Image.new("RGB", (8, 6)).save(root / "images" / name, format="PNG")
    return root


def one_line(root, *expect):
    with pytest.raises(DatasetError) as exc:
        load_dataset(root)
    text = str(exc.value)
    assert "\n" not in text and all(e in text for e in expect), text


def test_duplicate_image_names(tmp_path):
    one_line(colmap_text(tmp_path, [(POSE, "1", "a.png"), (POSE, "1", "a.png")]), "two images are named 'a.png'")


def test_missing_camera(tmp_path):
    one_line(
        colmap_text(tmp_path, [(POSE, "1", "a.png"), (POSE, "7", "b.png")]),
        "an image refers to camera 7, which the model's cameras file does not define",
    )


def test_zero_quaternion(tmp_path):
    one_line(colmap_text(tmp_path, [("0 0 0 0 0 0 5", "1", "a.png")]), "image 'a.png': rotation quaternion is zero")


def test_non_finite_pose(tmp_path):
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=8, height=6, params=[10, 10, 4, 3])
    )
    image = pycolmap.Image(image_id=1, name="a.png", camera_id=1)
    rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(np.eye(3)), [0, np.nan, 5]))
    (tmp_path / "sparse" / "0").mkdir(parents=True)
    rec.write_binary(str(tmp_path / "sparse" / "0"))
    (tmp_path / "images").mkdir()
    Image.new("RGB", (8, 6)).save(tmp_path / "images" / "a.png")
    one_line(tmp_path, "image 'a.png': translation: expected finite numbers, got nan")


def test_photo_name_longer_than_a_file_name(tmp_path):
    one_line(
        colmap_text(tmp_path, [(POSE, "1", "n" * 300 + ".png")], photo_names=[]),
        "photo name of 304 bytes",
        "at most 255 bytes",
    )


@pytest.mark.parametrize("fmt", ["BMP", "TIFF", "GIF"])
def test_photos_other_than_png_or_jpeg_are_refused_by_content(tmp_path, fmt):
    Image.new("RGB", (8, 6)).save(tmp_path / "a.png", format=fmt)  # named .png, holding another format
    with pytest.raises(DatasetError, match="a.png: not a PNG or JPEG photo \\(it starts with"):
        photos.photo_size(tmp_path / "a.png")


def test_a_jpeg_named_png_is_read_by_its_content(tmp_path):
    Image.new("RGB", (8, 6), (255, 0, 0)).save(tmp_path / "a.png", format="JPEG", quality=100)
    assert read_photo(tmp_path / "a.png").shape == (6, 8, 3)


def test_decode_budgets_are_checked_from_the_header(tmp_path, monkeypatch):
    path = tmp_path / "p.jpg"
    Image.new("RGB", (64, 48), (10, 200, 30)).save(path, format="JPEG", progressive=True)
    scans = path.read_bytes().count(photos.SOS)
    assert scans > 3 and read_photo(path).shape == (48, 64, 3)
    monkeypatch.setattr(photos, "MAX_JPEG_SCANS", 3)
    with pytest.raises(DatasetError, match=f"JPEG of {scans} scans; at most 3"):
        read_photo(path)
    mpo = tmp_path / "phone.jpg"  # a JPEG with a second picture appended (phones), which Pillow opens as MPO
    Image.new("RGB", (64, 48)).save(
        mpo, format="MPO", save_all=True, progressive=True, append_images=[Image.new("RGB", (64, 48))]
    )
    with pytest.raises(DatasetError, match="phone.jpg: JPEG of .* scans; at most 3"):
        read_photo(mpo)
    buf = io.BytesIO()
    Image.new("I;16", (64, 48)).save(buf, format="PNG")  # 16-bit grey: 2 bytes per pixel, then float32 RGBA
    (tmp_path / "p16.png").write_bytes(buf.getvalue())
    monkeypatch.setattr(photos, "MAX_DECODED_BYTES", 64 * 48 * 18 - 1)
    with pytest.raises(DatasetError, match="a 64x48 photo decodes to"):
        read_photo(tmp_path / "p16.png")


@pytest.mark.parametrize("arg", ["scene.ply:", ":data", ":"])
def test_scene_dataset_pairs_need_both_parts(tmp_path, monkeypatch, capsys, arg):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", arg]) == 2
    out, err = capsys.readouterr()
    assert (
        out == "" and err == f"gbviewer: error: {arg}: expected SCENE:DATASET with both parts (no such file either)\n"
    )


READ = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
from gbviewer.io.datasets import load_dataset
print(len(load_dataset(sys.argv[1]).views))
"""


def test_colmap_reads_under_an_address_space_limit_below_its_own(tmp_path):
    """ulimit -v 3 GiB: the reading child keeps that limit instead of failing to raise it to its own 4 GiB."""
    root = colmap_text(tmp_path, [(POSE, "1", "a.png"), (POSE, "1", "b.png")])
    limit = 3 << 30
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    assert soft == resource.RLIM_INFINITY or soft > limit, "the test needs room above its limit"
    out = subprocess.run(
        [sys.executable, "-c", READ, str(root), str(limit)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert out.returncode == 0 and out.stdout.strip() == "2", out.stderr


def blender_frames(root, splits: dict[str, list[tuple[str, np.ndarray]]], angles=None):
    """transforms_SPLIT.json of (photo, camera-to-world) frames, each photo an 8x6 RGBA PNG under root/photos."""
    import json

    (root / "photos").mkdir(exist_ok=True)
    for split, frames in splits.items():
        doc = {
            "camera_angle_x": (angles or {}).get(split, 0.7),
            "frames": [{"file_path": f"./photos/{name}", "transform_matrix": c2w.tolist()} for name, c2w in frames],
        }
        (root / f"transforms_{split}.json").write_text(json.dumps(doc))
        for name, _ in frames:
            Image.new("RGBA", (8, 6)).save(root / "photos" / f"{name}.png")


def test_blender_photo_listed_twice_with_the_same_camera_is_one_view(tmp_path):
    """An exporter that writes one file as transforms_train and transforms_test: each photo one view, in both
    splits; a pose written again through float32 still agrees."""
    moved = np.eye(4)
    moved[:3, 3] = [0.1, 0.2, 3.0]
    frames = [("a", np.eye(4)), ("b", moved)]
    again = [("a", np.eye(4)), ("b", moved.astype(np.float32).astype(np.float64)), ("c", np.eye(4))]
    blender_frames(tmp_path, {"train": frames, "test": again})
    data = load_dataset(tmp_path)
    assert [(v.name, v.split) for v in data.views] == [
        ("photos/a", "train+test"),
        ("photos/b", "train+test"),
        ("photos/c", "test"),
    ]
    assert [v.name for v in data.split("train")] == ["photos/a", "photos/b"]
    assert [v.name for v in data.split("test")] == ["photos/a", "photos/b", "photos/c"]
    assert len(data.split("all")) == 3


@pytest.mark.parametrize(
    "case, says", [("pose", "(train and test)"), ("angle", "(train and test)"), ("same split", "(test and test)")]
)
def test_blender_photo_of_two_different_frames_is_refused(tmp_path, case, says):
    moved = np.eye(4)
    moved[:3, 3] = [0.0, 0.0, 1e-3]
    if case == "same split":
        blender_frames(tmp_path, {"test": [("a", np.eye(4)), ("a", moved)]})
    else:
        blender_frames(
            tmp_path,
            {"train": [("a", np.eye(4))], "test": [("a", moved if case == "pose" else np.eye(4))]},
            angles={"test": 0.8 if case == "angle" else 0.7},
        )
    one_line(tmp_path, "'a.png' is the photo of two frames " + says, "with different cameras")


@pytest.mark.parametrize("kind", ["folder", "fifo", "broken link"])
def test_a_blender_split_file_that_is_not_a_file_is_one_line(tmp_path, kind):
    """transforms_train.json as a folder, a FIFO or a broken link was taken for an absent split: the dataset
    silently lost its training views."""
    blender_frames(tmp_path, {"train": [("a", np.eye(4))], "test": [("b", np.eye(4))]})
    path = tmp_path / "transforms_train.json"
    path.unlink()
    {"folder": path.mkdir, "fifo": lambda: os.mkfifo(path), "broken link": lambda: path.symlink_to("gone")}[kind]()
    one_line(tmp_path, "transforms_train.json: not a readable file")


@pytest.mark.parametrize("name", ["/etc/hostname", "../a.png"])
def test_photo_names_outside_the_photo_folder(tmp_path, name):
    one_line(
        colmap_text(tmp_path, [(POSE, "1", name)], photo_names=[]),
        f"photo name {name!r}",
        "expected a path inside this folder",
    )


def test_an_invalid_camera_names_the_model_and_the_image(tmp_path):
    one_line(
        colmap_text(tmp_path, [(POSE, "1", "a.png")], camera="1 PINHOLE 0 6 10 10 4 3\n"),
        str(tmp_path / "sparse" / "0"),
        "image 'a.png': camera 1: width: expected >= 1, got 0",
    )


@pytest.mark.parametrize(
    "images, camera, expect",
    [
        ([("1 0 0 0 nan 0 5", "1", "a.png")], CAMERA, "images.txt line 1: expected finite numbers, got 'nan' (item 6)"),
        ([(POSE, "1", "a.png"), ("1 0 0 0 0 x 5", "1", "b.png")], CAMERA, "images.txt line 3: expected finite numbers"),
        ([("1 0 0 0 0 0 inf", "1", "a.png")], CAMERA, "images.txt line 1: expected finite numbers, got 'inf'"),
        ([(POSE, "1.5", "a.png")], CAMERA, "images.txt line 1: expected an integer, got '1.5' (item 9)"),
        (
            [("1 0 0 0 0 0", "1", "a.png")],
            CAMERA,
            "images.txt line 1: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID",
        ),
        (
            [(POSE, "1", "a.png")],
            "1 FANCY 8 6 10 10 4 3\n",
            "cameras.txt line 1: unknown camera model 'FANCY'; "
            "supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV",
        ),
        (
            [(POSE, "1", "a.png")],
            "# c\n1 PINHOLE 8 6 10 nan 4 3\n",
            "cameras.txt line 2: PINHOLE parameters: expected finite numbers, got 'nan'",
        ),
        ([(POSE, "1", "a.png")], "1 PINHOLE 8 6 10 10 4\n", "cameras.txt line 1: PINHOLE has 4 parameters, got 3"),
        ([(POSE, "1", "a.png")], "1 PINHOLE 8.5 6 10 10 4 3\n", "cameras.txt line 1: expected an integer, got '8.5'"),
    ],
)
def test_a_malformed_text_model_names_the_file_and_line(tmp_path, images, camera, expect):
    """Checked before pycolmap, whose messages were its own internals ('[reconstruction_io_text.cc:189] Check
    failed: line_stream >> ...')."""
    one_line(colmap_text(tmp_path, images, camera=camera), str(tmp_path / "sparse" / "0"), expect)


def test_points_lines_are_counted_and_comments_skipped(tmp_path):
    root = colmap_text(tmp_path, [(POSE, "1", "a.png")])
    images = root / "sparse" / "0" / "images.txt"
    images.write_text(f"# header\n\n1 {POSE} 1 a.png\n1.5 2.5 -1 3 4 -1\n")
    assert [v.name for v in load_dataset(root).views] == ["a.png"]
    images.write_text(f"1 {POSE} 1 a.png\n1.5 2.5\n")
    one_line(root, "images.txt line 2: expected X Y POINT3D_ID triples (the image line's points), got 2 items")
