"""NeRF-synthetic (Blender) datasets: transforms_{train,test}.json with RGBA photos, camera-to-world matrices in
OpenGL axes (x right, y up, z backwards) and the horizontal field of view `camera_angle_x`."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...core.errors import CameraError, DatasetError, InvalidValue
from ...core.validate import array, field, read_json, real
from ...model.camera import Camera
from .dataset import BOTH, Dataset, View
from .photos import find_photo, missing_photos, photo_size

SPLIT_FILES = {"train": "transforms_train.json", "test": "transforms_test.json"}
GL_TO_CV = np.diag([1.0, -1.0, -1.0])  # flips y and z: OpenGL camera axes to OpenCV's


def is_blender(root: Path) -> bool:
    """Whether `root` holds a transforms_train.json or transforms_test.json."""
    return any((root / name).is_file() for name in SPLIT_FILES.values())


def blender_camera(c2w: np.ndarray, angle_x: float, width: int, height: int, name: str) -> Camera:
    """The world-to-camera pose of an OpenGL camera-to-world matrix and the centred pinhole of `angle_x`
    (radians across the width; square pixels)."""
    R = (c2w[:3, :3] @ GL_TO_CV).T
    f = 0.5 * width / math.tan(0.5 * angle_x)
    return Camera(width, height, f, f, width / 2, height / 2, R, -R @ c2w[:3, 3], name=name)


def _views(root: Path, split: str, path: Path) -> list[View]:
    """The views of one transforms file, each at its photo's size."""
    try:
        doc = read_json(path)
        angle = real(
            field(doc, "camera_angle_x", str(path)),
            f"{path}: 'camera_angle_x'",
            lo=0.0,
            lo_open=True,
            hi=math.pi - 1e-6,
        )
        frames = field(doc, "frames", str(path))
        if not isinstance(frames, list):
            raise InvalidValue(f"{path}: 'frames': expected a list")
        entries = []
        for k, frame in enumerate(frames):
            where = f"{path}: frame {k}"
            name = field(frame, "file_path", where)
            if not isinstance(name, str) or not name.strip():
                raise InvalidValue(f"{where}: 'file_path': expected a relative path")
            c2w = array(field(frame, "transform_matrix", where), f"{where}: 'transform_matrix'", (4, 4))
            if not np.array_equal(c2w[3], [0, 0, 0, 1]):
                raise InvalidValue(
                    f"{where}: 'transform_matrix': expected a bottom row [0, 0, 0, 1] (a rigid "
                    f"camera-to-world pose), got {np.round(c2w[3], 6).tolist()}"
                )
            entries.append((name.removeprefix("./"), c2w, where))
    except InvalidValue as exc:
        raise DatasetError(str(exc)) from None
    photos = [find_photo(root, name) for name, _, _ in entries]
    missing_photos(photos, str(path))
    views = []
    for (name, c2w, where), photo in zip(entries, photos):
        try:
            views.append(View(name, blender_camera(c2w, angle, *photo_size(photo), name), photo, split))
        except CameraError as exc:
            raise DatasetError(f"{where}: {exc}") from None
    return views


def load_blender(root: Path) -> Dataset:
    """The views of transforms_train.json and transforms_test.json (either may be absent, not both). A photo
    listed twice with the same camera (some exporters write one file as both splits) is one view, of both splits
    where they differ; with another camera it is a one-line DatasetError."""
    for name in SPLIT_FILES.values():  # one that is there but not a file (a folder, a FIFO, a broken link) is no split
        if not (root / name).is_file() and ((root / name).exists() or (root / name).is_symlink()):
            raise DatasetError(f"{root / name}: not a readable file; expected the split's transforms JSON")
    views = [
        v for split, name in SPLIT_FILES.items() if (root / name).is_file() for v in _views(root, split, root / name)
    ]
    seen: dict[Path, View] = {}
    for v in views:
        first = seen.setdefault(v.image, v)
        if first is v:
            continue
        if not same_camera(first.camera, v.camera):
            raise DatasetError(
                f"{root}: {v.image.name!r:.300} is the photo of two frames ({first.split} and "
                f"{v.split}) with different cameras; expected one pose per photo"
            )
        if v.split != first.split:
            seen[v.image] = replace(first, split=BOTH)
    return Dataset(root, "blender", tuple(seen.values()))


def same_camera(a: Camera, b: Camera) -> bool:
    """Whether two cameras agree to within float rounding (a pose written twice, through float32 or text)."""

    def numbers(c: Camera) -> np.ndarray:
        return np.concatenate([[c.width, c.height, c.fx, c.fy, c.cx, c.cy], np.ravel(c.R), np.ravel(c.t)])

    return bool(np.allclose(numbers(a), numbers(b), rtol=1e-6, atol=1e-6))
