"""COLMAP captures: `sparse/0` (binary or text) and the photos in `images/` (or images_2, ... of the same names),
read through pycolmap in a child process whose time and memory are bounded."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ...core.errors import CameraError, DatasetError, InvalidValue
from ...core.extras import require
from ...core.validate import array, real
from ...model.camera import Camera
from .colmap_text import check_text_model
from .dataset import Dataset, View, holdout_splits
from .photos import fit_to_photo, missing_photos, photo_path

MODEL_FILES = {".bin": ("cameras", "images", "rigs", "frames"), ".txt": ("cameras", "images", "rigs", "frames")}
EMPTY_POINTS = {".bin": b"\0" * 8, ".txt": b""}  # points3D is never read: it is large and unneeded here
PINHOLE = {"PINHOLE", "SIMPLE_PINHOLE"}
RADIAL = {"SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV"}  # pinhole when every distortion term is 0
BASE_MEMORY = 4 << 30  # the child's address space: pycolmap itself, plus MEMORY_PER_BYTE per byte of the model
SINGLE_THREADED = {"GLOG_minloglevel": "3", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}  # no per-core pools
MEMORY_PER_BYTE = 32
MIN_QUATERNION_NORM = 1e-6  # COLMAP normalises a pose's quaternion; one this short has no direction to keep
BASE_SECONDS, BYTES_PER_SECOND = 30.0, 5e6


def model_folder(root: Path) -> Path | None:
    """sparse/0, sparse or the folder itself: the first holding cameras.bin or cameras.txt."""
    for folder in (root / "sparse" / "0", root / "sparse", root):
        if any((folder / f"cameras{s}").is_file() for s in MODEL_FILES):
            return folder
    return None


def _stage(model: Path, into: Path) -> int:
    """Links to the model's files in `into` with an empty points3D (binary preferred, as COLMAP does; a text model
    checked line by line first, `check_text_model`); returns their size in bytes."""
    suffix = ".bin" if (model / "cameras.bin").is_file() else ".txt"
    if suffix == ".txt" and (model / "cameras.txt").is_file() and (model / "images.txt").is_file():
        check_text_model(model)
    size = 0
    for name in MODEL_FILES[suffix]:
        src = model / f"{name}{suffix}"
        if src.is_file():
            (into / src.name).symlink_to(src.resolve())
            size += src.stat().st_size
        elif name in ("cameras", "images"):
            raise DatasetError(f"{model}: unreadable COLMAP model: {src.name} missing")
    (into / f"points3D{suffix}").write_bytes(EMPTY_POINTS[suffix])
    return size


def read_colmap(model: Path) -> dict:
    """{"cameras": {id: {model, width, height, params, names}}, "images": [{name, camera, R, t}]} of the posed
    images, from pycolmap in a child process; a malformed model is a one-line `DatasetError`."""
    require("eval", "pycolmap", f"{model}: a COLMAP model", load=False)
    child = Path(__file__).with_name("colmap_child.py")
    with tempfile.TemporaryDirectory(prefix="gbviewer-colmap-") as tmp:
        size = _stage(model, Path(tmp))
        limit, seconds = BASE_MEMORY + MEMORY_PER_BYTE * size, BASE_SECONDS + size / BYTES_PER_SECOND
        try:
            out = subprocess.run(
                [sys.executable, str(child), tmp, str(limit)],
                capture_output=True,
                timeout=seconds,
                env={**os.environ, **SINGLE_THREADED},
            )
        except subprocess.TimeoutExpired:
            raise DatasetError(
                f"{model}: unreadable COLMAP model (pycolmap still reading after {seconds:.0f} s)"
            ) from None
    if out.returncode != 0 or not out.stdout:
        why = (out.stderr.decode(errors="replace").strip().splitlines() or [f"exit status {out.returncode}"])[-1]
        raise DatasetError(f"{model}: unreadable COLMAP model (pycolmap: {why[:200]})")
    try:  # the child's own output: NaN and Infinity kept, for `load_colmap` to name the image that has them
        doc = json.loads(out.stdout)
    except ValueError as exc:
        raise DatasetError(f"{model}: unreadable COLMAP model (pycolmap's output: {str(exc)[:100]})") from None
    if "error" in doc:
        rig = re.search(r"Rig with ID (\d+) does not exist", doc["error"])
        if rig and not any((model / f"rigs{s}").is_file() for s in MODEL_FILES):  # a trivial rig per camera
            raise DatasetError(
                f"{model}: an image refers to camera {rig[1]}, which the model's cameras file does not define"
            )
        raise DatasetError(f"{model}: unreadable COLMAP model ({doc['error'][:200]})")
    return doc


def pinhole(cam: dict, where: str) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy of a COLMAP camera (pycolmap's description); other models are refused by name."""
    model, values = cam["model"], dict(zip(cam["names"], cam["params"]))
    distortion = {k: v for k, v in values.items() if k not in ("f", "fx", "fy", "cx", "cy")}
    if model not in PINHOLE | RADIAL or any(v != 0 for v in distortion.values()):
        terms = ", ".join(f"{k}={v:g}" for k, v in distortion.items())
        raise DatasetError(
            f"{where}: camera model {model}{f' with distortion {terms}' if model in RADIAL else ''} "
            "is not supported; expected PINHOLE or SIMPLE_PINHOLE (undistort the photos: colmap "
            f"image_undistorter), or {', '.join(sorted(RADIAL))} with zero distortion"
        )
    fx, fy = (values["f"], values["f"]) if "f" in values else (values["fx"], values["fy"])
    return fx, fy, values["cx"], values["cy"]


def load_colmap(root: Path, model: Path, images: str = "images") -> Dataset:
    """The posed images of `model` with photos in root/`images`, split as HOLDOUT says; a camera's intrinsics are
    rescaled where its photo's size differs (images_4 of a full-size model)."""
    doc = read_colmap(model)
    posed = sorted(doc["images"], key=lambda im: im["name"])
    for a, b in zip(posed, posed[1:]):
        if a["name"] == b["name"]:
            raise DatasetError(f"{model}: two images are named {a['name']!r:.300}; expected one image per photo")
    folder = root / images
    paths = [photo_path(folder, im["name"]) for im in posed]
    if not folder.is_dir():
        raise DatasetError(f"{folder}: photo folder missing (choose another with --images)")
    missing_photos(paths, f"{folder} for {model}")
    split = holdout_splits([im["name"] for im in posed])
    views = []
    for im, path in zip(posed, paths):
        cam = doc["cameras"].get(im["camera"])
        where = f"{model}: image {im['name']!r}"
        if cam is None:
            raise DatasetError(f"{where}: camera {im['camera']} missing")
        try:
            q = array(im["q"], f"{where}: rotation quaternion", (4,))
            if np.linalg.norm(q) < MIN_QUATERNION_NORM:
                raise InvalidValue(
                    f"{where}: rotation quaternion is zero ({' '.join(f'{v:g}' for v in q)}); "
                    "expected a unit quaternion"
                )
            R, t = array(im["R"], f"{where}: R", (3, 3)), array(im["t"], f"{where}: translation", (3,))
            intrinsics = pinhole(cam, f"{where}: camera {im['camera']}")
            fx, fy, cx, cy = (real(v, f"{where}: intrinsics") for v in intrinsics)
        except InvalidValue as exc:
            raise DatasetError(str(exc)) from None
        try:
            camera = Camera(cam["width"], cam["height"], fx, fy, cx, cy, R, t, name=im["name"])
        except CameraError as exc:
            why = str(exc).removeprefix(f"camera {im['name']!r:.60}: ")
            raise DatasetError(f"{where}: camera {im['camera']}: {why}") from None
        views.append(View(im["name"], fit_to_photo(camera, path), path, split[im["name"]]))
    return Dataset(root, "colmap", tuple(views))
