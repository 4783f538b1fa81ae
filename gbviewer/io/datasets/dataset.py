"""A dataset's views: each photo with its camera and its split (train or test)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ...core.errors import DatasetError
from ...model.camera import Camera

SPLITS = ("train", "test", "all")
BOTH = "train+test"  # the split of a view in both
HOLDOUT = 8  # every 8th photo (name order) is a test view of a capture, as 3DGS and Mip-NeRF 360 do


@dataclass(frozen=True)
class View:
    """One photo: `camera` at the photo's own size (the evaluation's x1), `split` "train", "test" or BOTH (a Blender
    photo both transforms files list with the same camera)."""

    name: str
    camera: Camera
    image: Path
    split: str

    def in_split(self, name: str) -> bool:
        """Whether the view belongs to split `name` (train, test or all)."""
        return name == "all" or name in self.split.split("+")


@dataclass(frozen=True)
class Dataset:
    """The views of a dataset folder, in its order (name order for captures). format: colmap, blender or
    cameras.json."""

    root: Path
    format: str
    views: tuple[View, ...]

    def split(self, name: str) -> list[View]:
        """The views of split `name` (train, test or all); an empty one is a `DatasetError`."""
        if name not in SPLITS:
            raise DatasetError(f"split {name!r}; expected one of {', '.join(SPLITS)}")
        views = [v for v in self.views if v.in_split(name)]
        if not views:
            raise DatasetError(f"{self.root}: no {name} views among its {len(self.views)} ({self.format} dataset)")
        return views


def holdout_splits(names: list[str]) -> dict[str, str]:
    """name -> "test" for every HOLDOUT-th name in sorted order (the first included), "train" for the others."""
    return {n: "test" if k % HOLDOUT == 0 else "train" for k, n in enumerate(sorted(names))}
