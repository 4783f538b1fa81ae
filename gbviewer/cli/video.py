"""`gbviewer video`: side-by-side zoom videos."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.extras import require
from ..core.files import check_writable
from ..io import load
from ..model.camera_paths import MAX_FRAMES, PATHS, camera_path, nerfstudio_frames
from ..model.nerfstudio_paths import load_nerfstudio_path
from ..outputs.video import CODECS, CONTAINERS, MAX_FPS, MIN_FPS, record_video, video_encoder
from .argtypes import INSET, SIZE, Number, Rate, count, positive
from .options import (
    add_backend_arg,
    add_camera_args,
    add_load_args,
    add_lod_arg,
    add_stochastic_args,
    backend_of,
    camera_from_args,
    check_inset,
    check_render_size,
    load_options,
    path_args,
    settings_of,
)

VIDEO_PANE = (480, 360)  # default pane size of `gbviewer video`


def cmd_video(args: argparse.Namespace) -> int:
    """Side-by-side zoom video of several modes (H.264, H.265, VP9 or AV1; MP4 or WebM)."""
    require("video", "imageio_ffmpeg", "a video", load=False)
    settings = settings_of(args, precision="fast")
    if args.camera_path is not None:
        return _camera_path_video(args, settings)
    args.path = args.path or "zoom"
    path_args(args, PATHS, VIDEO_PANE)
    _check_out(args, [args.scene, args.cameras, None if args.path in PATHS else args.path])
    scene = load(args.scene, **load_options(args))
    cam = camera_from_args(scene, args)
    check_inset(args.inset, cam.width, cam.height)
    if args.path == "rate":
        check_render_size(cam.width, cam.height, [args.from_rate, args.to_rate], "--from/--to")
    args.fps = args.fps or 30.0
    path = camera_path(
        args.path,
        cam,
        args.frames,
        args.from_rate,
        args.to_rate,
        scene,
        args.up,
        fps=args.fps,
        seconds=args.seconds,
        max_frames=args.max_frames,
    )
    return _write(
        args,
        scene,
        path,
        settings,
        f"{args.path} " + (f"{args.from_rate:g} -> {args.to_rate:g} " if args.path in PATHS else ""),
    )


def _check_out(args: argparse.Namespace, inputs: list) -> None:
    """--out: writable, none of the inputs, a container that holds --codec and an encoder here for it."""
    check_writable(args.out, args.force, inputs=inputs, option="--out")
    video_encoder(args.out, args.codec, args.crf)


def _camera_path_video(args: argparse.Namespace, settings: list) -> int:
    """The video along a nerfstudio camera_path.json: its frames at its render size (or --size), at ns-render's
    frame rate (or --fps)."""
    _check_out(args, [args.scene, args.camera_path])
    p = load_nerfstudio_path(args.camera_path, args.size)
    path = nerfstudio_frames(p, args.frames, args.seconds, args.max_frames)
    check_inset(args.inset, *p.size)
    args.fps = args.fps or p.frame_rate
    scene = load(args.scene, **load_options(args))
    return _write(args, scene, path, settings, f"{Path(args.camera_path).name} ")


def _write(args: argparse.Namespace, scene, path: list, settings: list, what: str) -> int:
    """Record the video with a progress bar and say what was written."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("frames"),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
    )
    backend = backend_of(args)
    with Progress(*columns) as progress:
        task = progress.add_task(f"{Path(args.out).name}", total=len(path))
        info = record_video(
            scene,
            path,
            settings,
            args.out,
            fps=args.fps,
            backend=backend,
            inset=args.inset,
            codec=args.codec,
            crf=args.crf,
            force=args.force,
            progress=lambda done, total: progress.update(task, completed=done),
        )
    print(
        f"wrote {info.path}: {info.frames} frames of {info.width}x{info.height} at {info.fps:g} fps "
        f"({info.frames / info.fps:.1f} s), {args.codec}, {', '.join(s.label for s in settings)}, {what}"
        f"in {info.elapsed_s:.1f} s"
    )
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("video", help="side-by-side zoom video of several modes (H.264, H.265, VP9 or AV1; MP4 or WebM)")
    p.add_argument("scene", type=Path)
    add_load_args(p)
    add_camera_args(p)
    p.add_argument(
        "--modes",
        default="scalar,supersample:3,gaussian_blending",
        help="comma-separated MODE[:N][+fast|+exact][+lod[:PX]] (N x N supersampling, supersample:N = scalar:N; the "
        "level-of-detail cut at PX; gaussian_blending draws its fast kernel, within 1/1024 of +exact)",
    )
    add_lod_arg(p)
    add_stochastic_args(p)
    route = p.add_mutually_exclusive_group()
    route.add_argument(
        "--path",
        help="zoom (focal length), dolly (camera along its axis), rate (same view, rendered at the rate "
        "and nearest-upscaled) or a keyframes FILE.json (see gbviewer.model.keyframes.load_keyframes); default "
        "zoom",
    )
    route.add_argument(
        "--camera-path",
        type=Path,
        metavar="FILE.json",
        help="nerfstudio's camera_path.json (its viewer's export, ns-render's input): its frames at its "
        "render size (or --size) and frame rate (or --fps)",
    )
    p.add_argument("--from", dest="from_rate", type=Rate(), default=1.0, help="first sampling rate (default 1)")
    p.add_argument("--to", dest="to_rate", type=Rate(), default=1.0 / 8.0, help="last sampling rate (default 1/8)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--frames", type=count(), help="number of frames")
    length.add_argument("--seconds", type=positive(), help="length in seconds (default 4, or the keyframes' span)")
    p.add_argument(
        "--fps",
        type=Number(lo=MIN_FPS, hi=MAX_FPS),
        help=f"frames per second, {MIN_FPS:g}..{MAX_FPS:g} (default 30, or the camera path's)",
    )
    p.add_argument(
        "--max-frames",
        type=count(),
        default=MAX_FRAMES,
        help=f"refuse videos longer than this many frames (default {MAX_FRAMES})",
    )
    p.add_argument("--size", type=SIZE, metavar="WxH", help="size of each pane (default 480x360)")
    add_backend_arg(p)
    p.add_argument("--inset", type=INSET, metavar=INSET.metavar, help="magnify this region (x1 pixels) in a corner")
    p.add_argument(
        "--codec",
        choices=list(CODECS),
        default="h264",
        help="h264 (default), h265, vp9 or av1 (the container: --out's extension; WebM holds vp9 and av1)",
    )
    p.add_argument(
        "--crf",
        type=count(63, lo=0),
        metavar="0..63",
        help="constant quality of the codec (lower is better; h264/h265 0..51, vp9 0..63, av1 1..63; "
        + ", ".join(f"{k} {c.default_crf}" for k, c in CODECS.items())
        + " by default)",
    )
    p.add_argument("--out", required=True, help=" or ".join(f"FILE{e}" for e in CONTAINERS))
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_video)
