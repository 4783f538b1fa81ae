"""`gbviewer flicker`: shimmer as a number, per mode, along a camera path (gbviewer.outputs.flicker)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.errors import GBViewerError
from ..core.extras import require
from ..core.files import check_writable
from ..core.outputs import refuse_collisions
from ..io import load
from ..model.camera_paths import MAX_FRAMES
from ..outputs.console import wide_console
from ..outputs.flicker import (
    DEFAULT_DEGREES,
    DEFAULT_PAIRS,
    DEFAULT_REFERENCE,
    FLICKER_PATHS,
    flicker_path,
    heat_file,
    measure_flicker,
    write_heat_maps,
    write_heat_video,
    write_table,
)
from ..outputs.video import MAX_FPS, MIN_FPS
from ..render import RenderSettings
from .argtypes import SIZE, Number, Rate, count, positive
from .options import (
    MAX_COUNT,
    add_backend_arg,
    add_camera_args,
    add_load_args,
    add_lod_arg,
    add_stochastic_args,
    backend_of,
    camera_from_args,
    check_render_size,
    load_options,
    path_args,
    progress_bar,
    settings_of,
)

FLICKER_PANE = (320, 240)  # default pane size
VIDEO_NAME = "heat.mp4"


def cmd_flicker(args: argparse.Namespace) -> int:
    """Flicker per mode along a path: printed table, flicker.csv/json, heat maps and optionally their video."""
    if args.video:
        require("video", "imageio_ffmpeg", "--video", load=False)
    settings = settings_of(args)
    try:
        reference = RenderSettings.parse(args.reference)
    except GBViewerError as exc:
        raise GBViewerError(f"--reference {args.reference}: {exc}") from None
    path_args(args, FLICKER_PATHS, FLICKER_PANE)
    out = Path(args.out)
    outputs = [out / "flicker.csv", out / "flicker.json", *(heat_file(out, s.spec) for s in settings)]
    outputs += [out / VIDEO_NAME] if args.video else []
    refuse_collisions(outputs)
    inputs = [args.scene, args.cameras, None if args.path in FLICKER_PATHS else args.path]
    for path in outputs:
        check_writable(path, args.force, inputs=inputs, option="--out")
    scene = load(args.scene, **load_options(args))
    cam = camera_from_args(scene, args)
    if args.path == "rate":
        check_render_size(cam.width, cam.height, [args.from_rate, args.to_rate], "--from/--to")
    path = flicker_path(
        args.path,
        cam,
        scene,
        args.frames,
        args.from_rate,
        args.to_rate,
        degrees=args.degrees,
        up=args.up,
        fps=args.fps,
        seconds=args.seconds,
        max_frames=args.max_frames,
    )
    backend = backend_of(args)
    total = min(args.pairs, max(1, len(path) - 1)) * 2 * (len(settings) + 2)
    with progress_bar("flicker", total) as advance:
        report = measure_flicker(
            scene,
            path,
            settings,
            reference=reference,
            pairs=args.pairs,
            backend=backend,
            keep_pairs=args.video,
            path_name=str(args.path),
            progress=lambda _: advance(1),
            accumulate=args.accumulate,
        )
    print_report(report, cam.width, cam.height)
    written = write_table(out, report, args.force) + write_heat_maps(out, report, args.force)
    if args.video:
        written.append(write_heat_video(out / VIDEO_NAME, report, path, args.fps, args.force))
    for p in written:
        print(f"wrote {p}")
    return 0


def print_report(report, width: int, height: int) -> None:
    """The table: flicker, change and flicker over the floor per mode, then the reference and the floor."""
    from rich.table import Table

    t = Table(
        title=f"Flicker along {report.path} ({len(report.starts)} pairs of {report.frames} frames, "
        f"{width}x{height}; 8-bit levels, vs {report.reference})"
    )
    for col in ("mode", "flicker", "change", "x floor"):
        t.add_column(col, justify="left" if col == "mode" else "right")
    for row in report.rows():
        t.add_row(
            row["label"],
            f"{row['flicker']:.3f}",
            f"{row['change']:.3f}",
            "-" if row["vs_floor"] is None else f"{row['vs_floor']:.2f}",
        )
    floor = "" if report.floor is None else f"; floor ({report.floor.spec} vs it): {report.floor.flicker:.3f}"
    t.caption = f"reference {report.reference}: change {report.reference_change:.3f}{floor}"
    wide_console().print(t)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("flicker", help="temporal stability per mode along a camera path: table, heat maps, video")
    p.add_argument("scene", type=Path)
    add_load_args(p)
    add_camera_args(p)
    p.add_argument(
        "--modes",
        default="scalar,mip,analytic,gaussian_blending,supersample:3",
        help="comma-separated MODE, MODE:N, supersample:N or preset:NAME, each with +lod[:PX] optionally",
    )
    add_lod_arg(p)
    add_stochastic_args(p)
    p.add_argument(
        "--reference",
        default=DEFAULT_REFERENCE,
        help=f"the dense reference whose change is subtracted (default {DEFAULT_REFERENCE}, sorted by "
        "centre depth as scalar is; stopthepop:0:8 is popping-free: the exact per-pixel order); the floor "
        "is it at half its samples per axis",
    )
    p.add_argument(
        "--path",
        default="zoom",
        help="zoom, dolly, rate (as gbviewer video), orbit (about the scene's centre, --degrees) or a "
        "keyframes FILE.json",
    )
    p.add_argument("--from", dest="from_rate", type=Rate(), default=1.0, help="first sampling rate (default 1)")
    p.add_argument("--to", dest="to_rate", type=Rate(), default=1.0 / 8.0, help="last sampling rate (default 1/8)")
    p.add_argument(
        "--degrees",
        type=Number(lo=-360.0, hi=360.0),
        default=DEFAULT_DEGREES,
        help=f"azimuth swept by --path orbit (default {DEFAULT_DEGREES:g})",
    )
    length = p.add_mutually_exclusive_group()
    length.add_argument("--frames", type=count(lo=2), help="frames of the path, at least 2 (default: 4 s at --fps)")
    length.add_argument("--seconds", type=positive(), help="length of the path in seconds")
    p.add_argument(
        "--fps",
        type=Number(lo=MIN_FPS, hi=MAX_FPS),
        default=30.0,
        help="frames per second of the path (and of --video)",
    )
    p.add_argument("--max-frames", type=count(), default=MAX_FRAMES, help="refuse longer paths")
    p.add_argument(
        "--pairs",
        type=count(MAX_COUNT),
        default=DEFAULT_PAIRS,
        help=f"pairs of consecutive frames measured, spread over the path (default {DEFAULT_PAIRS})",
    )
    p.add_argument(
        "--accumulate",
        type=count(MAX_COUNT),
        default=1,
        help="stochastic modes: show each frame as the mean of this many frame indices, as a still "
        "viewer pane after that many frames (default 1: one sample per pixel per frame)",
    )
    p.add_argument("--size", type=SIZE, metavar="WxH", help="pane size (default 320x240)")
    add_backend_arg(p)
    p.add_argument("--out", required=True, help="folder for flicker.csv, flicker.json, heat-MODE.png (and heat.mp4)")
    p.add_argument("--video", action="store_true", help=f"also write {VIDEO_NAME}: the heat maps pair by pair")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=cmd_flicker)
