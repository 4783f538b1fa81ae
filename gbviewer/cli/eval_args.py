"""`gbviewer eval`'s options and which scene goes with which dataset."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.errors import GBViewerError
from ..io.datasets import SPLITS
from ..render import BACKENDS
from ..render.types import MAX_THREADS
from .argtypes import BACKGROUND, Rate, count

SCENE_SUFFIXES = (".ply", ".splat", ".spz", ".sog")
MAX_WORKERS = 1024


def add_dataset_args(p: argparse.ArgumentParser) -> None:
    """--data and --images: a scene's training dataset (`gbviewer eval`, and the viewer's photo pane)."""
    p.add_argument(
        "--data",
        type=Path,
        help="the dataset: a COLMAP capture (sparse/0 and images/), a Blender "
        "folder (transforms_train/test.json) or a 3DGS cameras.json (with its photos in --images)",
    )
    p.add_argument(
        "--images",
        default="images",
        help="photo folder of a COLMAP capture or a cameras.json, beside "
        "it (default images; images_4 for quarter-size photos: x1 is the photos' resolution)",
    )


def add_eval_args(p: argparse.ArgumentParser) -> None:
    """The arguments of `gbviewer eval` (every number through argtypes)."""
    p.add_argument(
        "scenes",
        nargs="+",
        metavar="SCENE",
        help="a scene file (with --data), SCENE:DATASET, or a "
        "folder of scene files (with --data: a folder holding a dataset named as each scene)",
    )
    add_dataset_args(p)
    p.add_argument(
        "--modes",
        default="scalar,mip,analytic,gaussian_blending",
        help="comma-separated MODE[:N][+lod[:PX]] (N x N supersampling, the level-of-detail cut at PX)",
    )
    p.add_argument(
        "--rates",
        type=Rate(many=True),
        default="1,1/2,1/4,1/8",
        help="sampling rates 1/k: the photos box-downsampled by k are the ground truth (default 1,1/2,1/4,1/8)",
    )
    p.add_argument(
        "--split",
        default="test",
        choices=SPLITS,
        help="views to evaluate (default test: every 8th photo of a capture, transforms_test.json of a Blender set)",
    )
    p.add_argument(
        "--background",
        type=BACKGROUND,
        metavar=BACKGROUND.metavar,
        help="background of the renders and of RGBA photos (1,1,1 for a Blender scene trained on white); "
        "default: the viewer's, the photos' backdrop (their borders' median colour) where every photo is "
        "opaque, else black; each table says which",
    )
    p.add_argument(
        "--backend",
        default="auto",
        choices=["auto", *BACKENDS],
        help="auto (default): the backend auto picks in each worker (see gbviewer info)",
    )
    runner = p.add_mutually_exclusive_group()
    runner.add_argument("--workers", type=count(MAX_WORKERS), default=1, help="local processes (default 1)")
    runner.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run on a Ray cluster (host:port, ray://host:port, auto; local: a Ray instance started for the run)",
    )
    p.add_argument(
        "--threads",
        type=count(MAX_THREADS),
        help="CPU threads per render (default: the cores shared among --workers; on Ray 4 per task)",
    )
    p.add_argument("--cache", type=Path, help="folder of box-downsampled photos (default: the user cache folder)")
    p.add_argument("--json", type=Path, help="write every view's numbers here")
    p.add_argument("--plots", type=Path, help="write PNG plots (PSNR and SSIM against the rate) into this folder")
    p.add_argument("--force", action="store_true", help="overwrite existing --json/--plots files")


def _folder_scenes(folder: Path) -> list[Path]:
    """The scene files (and SOG folders) in `folder`, by name."""
    return [
        f
        for f in sorted(folder.iterdir())
        if (f.is_file() and f.suffix.lower() in SCENE_SUFFIXES) or (f.is_dir() and (f / "meta.json").is_file())
    ]


def scene_pairs(scenes: list[str], data: Path | None) -> list[tuple[Path, Path]]:
    """(scene, dataset) for each SCENE argument: SCENE with --data, SCENE:DATASET, or each scene of a folder with
    the dataset named as it (its file name without the suffix) in --data; SCENE:DATASET with --data is refused
    (which dataset?)."""
    pairs: list[tuple[Path, Path]] = []
    for arg in scenes:
        path = Path(arg)
        if not path.exists() and ":" in arg:
            scene, _, dataset = arg.rpartition(":")
            if not scene.strip() or not dataset.strip():
                raise GBViewerError(f"{arg}: expected SCENE:DATASET with both parts (no such file either)")
            if data is not None:
                raise GBViewerError(
                    f"{arg}: SCENE:DATASET names its dataset; --data {data} too is ambiguous (give one of them)"
                )
            pairs.append((Path(scene), Path(dataset)))
        elif data is None:
            raise GBViewerError(f"{arg}: which dataset? give --data DATASET or {arg}:DATASET")
        elif path.is_dir() and not (path / "meta.json").is_file():
            found = _folder_scenes(path)
            if not found:
                raise GBViewerError(f"{path}: no scene files ({', '.join(SCENE_SUFFIXES)}) in this folder")
            pairs += [(f, data / f.stem) for f in found]
        else:
            pairs.append((path, data))
    return pairs
