"""Training datasets: the photos a scene was trained on, their cameras and the train/test split.

`load_dataset(path)` reads a COLMAP capture (sparse/0 + images/), a NeRF-synthetic Blender folder
(transforms_{train,test}.json) or a 3DGS cameras.json with a photo folder, and returns a `Dataset` whose views
hold gbviewer `Camera`s at each photo's own size."""

from __future__ import annotations

from pathlib import Path

from ...core.errors import CameraError, DatasetError
from ...model.camera import load_cameras_json
from .blender import is_blender, load_blender
from .colmap import load_colmap, model_folder
from .dataset import HOLDOUT, SPLITS, Dataset, View, holdout_splits
from .photos import find_photo, fit_to_photo, missing_photos, read_photo

__all__ = ["HOLDOUT", "SPLITS", "Dataset", "View", "load_dataset", "read_photo"]

FORMATS = (
    "a COLMAP capture (sparse/0 and images/), a Blender folder (transforms_train/test.json) or a 3DGS "
    "cameras.json with its photos"
)


def load_cameras_dataset(path: Path, images: str = "images") -> Dataset:
    """A 3DGS cameras.json and the photos named by its img_name in the folder `images` beside it, split as
    HOLDOUT says (3DGS lists its test cameras in cameras.json too)."""
    try:
        cams = load_cameras_json(path)
    except CameraError as exc:
        raise DatasetError(str(exc)) from None
    folder = path.parent / images
    photos = [find_photo(folder, c.name) for c in cams]
    missing_photos(photos, str(path))
    split = holdout_splits([c.name for c in cams])
    if len(split) != len(cams):
        raise DatasetError(f"{path}: {len(cams) - len(split)} cameras share an img_name with another")
    pairs = sorted(zip(cams, photos), key=lambda pair: pair[0].name)
    return Dataset(
        path.parent,
        "cameras.json",
        tuple(View(c.name, fit_to_photo(c, p, larger=True), p, split[c.name]) for c, p in pairs),
    )


def load_dataset(path: str | Path, images: str = "images") -> Dataset:
    """The dataset at `path`, its format told by its files; `images`: the photo folder of a COLMAP capture or a
    cameras.json (images_4 for the quarter-size photos)."""
    path = Path(path)
    if path.is_file() and path.suffix == ".json":
        return load_cameras_dataset(path, images)
    if not path.is_dir():
        raise DatasetError(
            f"{path}: no such dataset folder"
            if not path.exists()
            else f"{path}: expected a dataset folder or a cameras.json"
        )
    if is_blender(path):
        return load_blender(path)
    model = model_folder(path)
    if model is not None:
        return load_colmap(path, model, images)
    if (path / "cameras.json").is_file():
        return load_cameras_dataset(path / "cameras.json", images)
    raise DatasetError(f"{path}: not a dataset; expected {FORMATS}")
