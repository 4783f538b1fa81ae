"""`gbviewer view` (the desktop viewer) and `gbviewer demo` (its no-display comparison images and zoom video)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from .. import DEFAULT_SCENE
from ..core.errors import GBViewerError
from ..core.extras import require
from ..core.files import check_writable
from ..io import load
from ..io.datasets import load_dataset
from ..model.camera_paths import zoom_path
from ..outputs.figure import compose_grid, render_grid, save_image
from ..outputs.video import record_video
from ..render import Mode, RenderSettings
from .argtypes import BACKGROUND
from .eval_args import add_dataset_args
from .options import add_backend_arg, add_camera_args, backend_of, camera_from_args

DEMO_VIDEO_FRAMES = 36  # 3 s at 12 fps
DEMO_FILES = ("comparison.png", "zoom.mp4")  # what demo writes into --out
DEMO_SETTINGS = [
    RenderSettings(Mode.SCALAR),
    RenderSettings(Mode.SCALAR, supersample=3),
    RenderSettings(Mode.GAUSSIAN_BLENDING, precision="fast"),  # as the viewer's panes
]


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job without a window: side-by-side comparison of the bundled (or given) scene at x1 and x1/8, and
    a short x1 -> x1/8 zoom video of the same modes."""
    from rich.progress import Progress

    require("video", "imageio_ffmpeg", "the demo's zoom video", load=False)
    scene_path = args.scene or DEFAULT_SCENE
    out_dir, force, args.cameras = Path(args.out), getattr(args, "force", False), getattr(args, "cameras", None)
    for name in DEMO_FILES:
        check_writable(out_dir / name, force, inputs=[scene_path, args.cameras], option="--out")
    scene = load(scene_path)
    cam = camera_from_args(scene, args)
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print("no display found: writing the comparison images instead of opening a window")
    cells = render_grid(scene, cam, DEMO_SETTINGS, [1.0, 1.0 / 8.0], backend_of(args))
    img = compose_grid(cells, cam.width, cam.height)
    path = save_image(out_dir / DEMO_FILES[0], img, force=force)
    print(
        f"wrote {path} ({img.width}x{img.height}): {Path(scene_path).name}, "
        + ", ".join(f"{c.settings.label} {c.total_ms:.0f} ms" for c in cells[0])
    )
    small = cam.with_size(max(2, cam.width // 2), max(2, cam.height // 2))  # half size keeps it quick
    frames = zoom_path(small, DEMO_VIDEO_FRAMES)
    with Progress(transient=True) as progress:
        task = progress.add_task("zoom video", total=len(frames))
        info = record_video(
            scene,
            frames,
            DEMO_SETTINGS,
            out_dir / DEMO_FILES[1],
            fps=12,
            backend=args.backend,
            force=force,
            progress=lambda done, total: progress.update(task, completed=done),
        )
    print(f"wrote {info.path} ({len(frames)} frames, x1 -> x1/8, {' | '.join(s.label for s in DEMO_SETTINGS)})")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """`gbviewer [SCENE] [--data DATASET]`: the desktop viewer (with the dataset's photos); without a display, say so
    and write the comparison instead."""
    from ..app import has_display_env, open_window

    for path, what in ((args.scene, ""), (args.data, "--data ")):
        if path is not None and not path.exists():
            raise GBViewerError(f"{what}{path}: no such file or folder")
    opened, why = open_window(
        args.scene,
        args.cameras,
        projection=args.projection,
        backend=args.backend,
        data=args.data,
        images=args.images,
        background=args.background,
    )
    if opened:
        return 0
    if args.data is not None:  # checked as the viewer would, before anything is written
        dataset = load_dataset(args.data, args.images)
        print(
            f"--data {args.data}: {len(dataset.views)} views read; the no-display fallback does not use the "
            f"dataset's photos"
        )
    if has_display_env()[0]:  # (without one, demo says so itself)
        print(f"cannot open the viewer window: {why}; writing the comparison images instead")
    return cmd_demo(args)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="open the desktop viewer (what `gbviewer [SCENE]` runs); without a display, "
        "write the comparison images like demo",
    )
    p.add_argument("scene", type=Path, nargs="?")
    add_camera_args(p)
    add_backend_arg(
        p,
        None,
        "the viewer's backend, as its panel sets it (default: the one it saved, auto at first), "
        "and that of the no-display fallback (default auto)",
    )
    add_dataset_args(p)
    p.add_argument(
        "--background",
        type=BACKGROUND,
        metavar=BACKGROUND.metavar,
        help="the panes' background, saved (default: the saved one, black at first; with --data of "
        "opaque photos, their backdrop: the median colour of their borders)",
    )
    p.add_argument("--out", default="out", help="output folder of the no-display fallback (default ./out)")
    p.add_argument("--force", action="store_true", help="overwrite the no-display fallback's existing files")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser("demo", help="write the side-by-side comparison of the bundled scene to a folder")
    p.add_argument("scene", type=Path, nargs="?")
    add_camera_args(p)
    add_backend_arg(p)
    p.add_argument("--out", default="out", help=f"output folder (default ./out) for {' and '.join(DEMO_FILES)}")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.set_defaults(func=cmd_demo)
