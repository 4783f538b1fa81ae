"""The viewer's camera path: keyframes added from the view, imported from and exported to nerfstudio's
camera_path.json (gbviewer.model.nerfstudio_paths), and the frames the Record video button renders along it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ...core.errors import GBViewerError
from ...core.validate import read_json
from ...model.camera import Camera
from ...model.camera_paths import PathFrame, nerfstudio_frames
from ...model.keyframes import Keyframe
from ...model.nerfstudio_paths import (
    NerfstudioPath,
    is_nerfstudio_path,
    load_nerfstudio_path,
    path_from_keyframes,
    save_nerfstudio_path,
)

SECONDS_PER_KEY = 2.0  # between keys added in the viewer (nerfstudio's viewer's default transition)
PATH_FPS = 30.0


def is_nerfstudio_file(path: str | Path) -> bool:
    """A .json the viewer imports as a camera path rather than as training cameras."""
    try:
        return Path(path).suffix.lower() == ".json" and is_nerfstudio_path(read_json(path))
    except GBViewerError:  # unreadable: opened as cameras, whose reader names the problem
        return False


class PathKeys:
    """Keyframes of the view, or an imported camera_path.json (kept whole: exported again as it was read)."""

    def __init__(self) -> None:
        self.keys: list[Camera] = []
        self.imported: NerfstudioPath | None = None
        self.source: Path | None = None

    def __len__(self) -> int:
        return len(self.imported.frames or self.imported.keys) if self.imported else len(self.keys)

    def add(self, camera: Camera) -> None:
        """A key at this camera, SECONDS_PER_KEY after the last; an imported path becomes its keys first."""
        if self.imported is not None:
            self.keys = [k.camera.with_size(camera.width, camera.height) for k in self.imported.keys]
            self.imported = None
        if self.keys and (self.keys[0].width, self.keys[0].height) != (camera.width, camera.height):
            camera = camera.with_size(self.keys[0].width, self.keys[0].height)
        self.keys.append(camera)

    def clear(self) -> None:
        self.keys, self.imported, self.source = [], None, None

    def import_file(self, path: str | Path) -> NerfstudioPath:
        """Read a camera_path.json (one-line errors as `load_nerfstudio_path`)."""
        self.imported = load_nerfstudio_path(path)
        self.keys, self.source = [], Path(path)
        return self.imported

    def path(self) -> NerfstudioPath:
        """The imported path, or one through the added keys (SECONDS_PER_KEY apart, PATH_FPS)."""
        if self.imported is not None:
            return self.imported
        keys = [Keyframe(c, 1.0, i * SECONDS_PER_KEY) for i, c in enumerate(self.keys)]
        return path_from_keyframes(keys, PATH_FPS)

    def export(self, out: str | Path, force: bool = False) -> Path:
        return save_nerfstudio_path(self.path(), out, force)

    def frames(self, width: int) -> list[PathFrame]:
        """The path's frames (an imported file's camera_path list, as ns-render renders it) at `width` pixels wide
        (even height), the field of view kept."""
        out = []
        for pf in nerfstudio_frames(self.path()):
            c = pf.camera
            h = max(2, round(width * c.height / c.width / 2) * 2)
            f = c.fy * h / c.height  # nerfstudio's square pixels: the vertical field of view sets both
            out.append(PathFrame.of(replace(c, width=width, height=h, fx=f, fy=f, cx=width / 2, cy=h / 2)))
        return out

    @property
    def frame_rate(self) -> float:
        return self.path().frame_rate
