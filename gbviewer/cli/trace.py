"""`gbviewer trace`: what the CPU kernel did at one pixel."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.errors import GBViewerError
from ..core.files import check_writable
from ..io import load
from ..render import trace_pixel
from .argtypes import BACKGROUND, PIXEL, Rate, count
from .options import (
    MAX_COUNT,
    add_camera_args,
    add_load_args,
    add_stochastic_args,
    camera_from_args,
    check_render_size,
    load_options,
    settings_of,
)


def cmd_trace(args: argparse.Namespace) -> int:
    """Pixel traces of the CPU kernel, one rich table per mode; --json writes them all."""
    from ..outputs.trace_report import print_traces, write_traces

    if args.json:
        check_writable(args.json, args.force, inputs=[args.scene, args.cameras], option="--json")
    settings = settings_of(args)
    scene = load(args.scene, **load_options(args))
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, [args.scale], "--scale")
    cam = cam.at_sampling_rate(args.scale)
    x, y = args.pixel
    if x >= cam.width or y >= cam.height:
        raise GBViewerError(
            f"--pixel {x},{y}: outside the {cam.width}x{cam.height} image at --scale "
            f"{args.scale:g} (x in 0..{cam.width - 1}, y in 0..{cam.height - 1})"
        )
    traces = [trace_pixel(scene, cam, x, y, s) for s in settings]
    print_traces(traces, args.top)
    if args.json:
        print(f"wrote {write_traces(Path(args.json), traces, str(args.scene), args.force)}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "trace",
        help="what the CPU kernel did at one pixel, splat by splat, per mode: top "
        "contributors, rejections, colour and transmittance (tables; --json)",
    )
    p.add_argument("scene", type=Path)
    add_load_args(p)
    add_camera_args(p)
    p.add_argument(
        "--pixel",
        type=PIXEL,
        required=True,
        metavar=PIXEL.metavar,
        help="the output pixel, from 0 (x right, y down) in the image at --scale",
    )
    p.add_argument(
        "--modes",
        default="scalar,gaussian_blending",
        help="comma-separated MODE[:N][+lod[:PX]] (N x N supersampling, supersample:N = scalar:N; "
        "preset:NAME; the level-of-detail cut at PX)",
    )
    p.add_argument(
        "--supersample",
        type=count(8),
        metavar="1..8",
        help="N x N samples for the modes given without :N (one with another :N is refused)",
    )
    add_stochastic_args(p)
    p.add_argument("--scale", type=Rate(), default=1.0, help="sampling rate: 8, 1, 0.125 or 1/8")
    p.add_argument(
        "--background",
        type=BACKGROUND,
        default=(0.0, 0.0, 0.0),
        metavar=BACKGROUND.metavar,
        help="background colour, each in 0..1",
    )
    p.add_argument("--top", type=count(MAX_COUNT), default=10, help="contributors shown per mode (default 10)")
    p.add_argument("--json", help="write every trace here (FILE.json; see gbviewer.PixelTrace.to_json)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    p.set_defaults(func=cmd_trace)
