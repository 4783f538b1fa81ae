"""Small synthetic training datasets the tests build: the bundled scene rendered densely (scalar, 8 x 8
supersampling) as the "photos" from views around it, written as a COLMAP capture (binary or text, through
pycolmap), a Blender folder (transforms_{train,test}.json with RGBA PNGs) and a 3DGS cameras.json."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import gbviewer as gb
from gbviewer.model.camera import frame_box, orbit_direction
from gbviewer.outputs.figure import to_uint8

W, H = 130, 100  # not multiples of 8: the ragged edges box-downsampling crops
VIEWS = 9  # names v00..v08: v00 and v08 are the capture's test views (every 8th)
SUPERSAMPLE = 8


@dataclass(frozen=True)
class Shot:
    """A view of the synthetic dataset: its camera, the eye it was built from and its photo (RGB, alpha)."""

    name: str
    camera: gb.Camera
    eye: np.ndarray
    rgb: np.ndarray
    alpha: np.ndarray


def shots(scene: gb.Scene, n: int = VIEWS, vary: bool = True) -> list[Shot]:
    """n views around the scene with their dense renders on black; with `vary`, every other view has an
    off-centre principal point and fy != fx (Blender cameras cannot)."""
    centre, _, dist = frame_box(*scene.robust_bounds(), 45.0, W / H)
    out = []
    for i in range(n):
        eye = centre + dist * orbit_direction(np.array([0.0, -1.0, 0.0]), 360.0 * i / n, 15.0 + 3 * i)
        cam = gb.Camera.look_at(eye, centre, (0.0, -1.0, 0.0), W, H, 45.0, name=f"v{i:02d}")
        if vary and i % 2:
            cam = replace(cam, fy=cam.fx * 1.03, cx=cam.cx + 2.25, cy=cam.cy - 1.5)
        frame = gb.render(scene, cam, "scalar", supersample=SUPERSAMPLE)
        out.append(Shot(cam.name, cam, eye, frame.rgb, frame.alpha))
    return out


def save_rgb(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(to_uint8(rgb)).save(path)


def save_rgba(path: Path, rgb: np.ndarray, alpha: np.ndarray) -> None:
    """Straight RGBA of a render on black (rgb is premultiplied): colour rgb / alpha, 0 where alpha is 0."""
    straight = np.where(alpha[..., None] > 0, rgb / np.maximum(alpha[..., None], 1e-8), 0.0)
    rgba = np.concatenate([to_uint8(straight), to_uint8(alpha[..., None])], axis=-1)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgba, "RGBA").save(path)


def write_colmap(
    root: Path, views: list[Shot], text: bool = False, model: str | None = None, extra: tuple[float, ...] = ()
) -> Path:
    """root/sparse/0 (through pycolmap) and root/images/NAME.png: odd views use a PINHOLE camera, even ones a
    SIMPLE_PINHOLE (fx = fy); `model` with `extra` parameters (after f, cx, cy for SIMPLE_* models, else fx, fy,
    cx, cy) replaces the PINHOLE one."""
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction()
    for i, shot in enumerate(views):
        c = shot.camera
        if i % 2 and model is not None:
            params = [c.fx, c.cx, c.cy, *extra] if model.startswith("SIMPLE") else [c.fx, c.fy, c.cx, c.cy, *extra]
            cam = pycolmap.Camera(camera_id=i + 1, model=model, width=W, height=H, params=params)
        elif i % 2:
            cam = pycolmap.Camera(camera_id=i + 1, model="PINHOLE", width=W, height=H, params=[c.fx, c.fy, c.cx, c.cy])
        else:
            cam = pycolmap.Camera(camera_id=i + 1, model="SIMPLE_PINHOLE", width=W, height=H, params=[c.fx, c.cx, c.cy])
        rec.add_camera_with_trivial_rig(cam)
        image = pycolmap.Image(image_id=i + 1, name=f"{shot.name}.png", camera_id=i + 1)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(c.R), c.t))
        save_rgb(root / "images" / f"{shot.name}.png", shot.rgb)
    model_dir = root / "sparse" / "0"
    model_dir.mkdir(parents=True)
    (rec.write_text if text else rec.write_binary)(str(model_dir))
    return root


def write_blender(root: Path, views: list[Shot], test: tuple[int, ...] = (0, 8)) -> Path:
    """transforms_train.json and transforms_test.json (views at `test`; a split without views gets no file) with
    RGBA photos; the views' cameras must be centred with square pixels (`shots(vary=False)`)."""
    for split in ("train", "test"):
        chosen = [s for i, s in enumerate(views) if (i in test) == (split == "test")]
        if not chosen:
            continue
        frames = []
        for s in chosen:
            c2w = np.eye(4)
            c2w[:3, :3] = s.camera.R.T @ np.diag([1.0, -1.0, -1.0])
            c2w[:3, 3] = s.eye
            frames.append({"file_path": f"./{split}/{s.name}", "transform_matrix": c2w.tolist()})
            save_rgba(root / split / f"{s.name}.png", s.rgb, s.alpha)
        angle = 2 * np.arctan(0.5 * W / chosen[0].camera.fx)
        (root / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": angle, "frames": frames}))
    return root


def write_cameras_json(root: Path, views: list[Shot]) -> Path:
    """A 3DGS cameras.json (rotation: camera-to-world, position: the eye) and images/NAME.png."""
    entries = [
        {
            "id": k,
            "img_name": s.name,
            "width": W,
            "height": H,
            "fx": s.camera.fx,
            "fy": s.camera.fy,
            "rotation": s.camera.R.T.tolist(),
            "position": s.eye.tolist(),
        }
        for k, s in enumerate(views)
    ]
    root.mkdir(parents=True, exist_ok=True)
    (root / "cameras.json").write_text(json.dumps(entries))
    for s in views:
        save_rgb(root / "images" / f"{s.name}.png", s.rgb)
    return root
