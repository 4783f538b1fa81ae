"""`gbviewer compare`: labelled grids of modes x sampling rates."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.files import check_writable
from ..io import load
from ..io.datasets.backdrop import choose_background
from ..model.camera import format_rate
from ..outputs.figure import DIFFS, write_comparison
from ..render.presets import differences
from .argtypes import BACKGROUND, INSET, Rate
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
    settings_of,
)


def cmd_compare(args: argparse.Namespace) -> int:
    """Labelled grid of modes x sampling rates with PSNR under each cell."""
    settings = settings_of(args, precision="fast")
    background = choose_background(args.background, None)
    rates = args.rates
    check_writable(args.out, args.force, inputs=[args.scene, args.cameras], option="--out")
    scene = load(args.scene, **load_options(args))
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, rates, "--rates")
    check_inset(args.inset, cam.width, cam.height)
    cmp = write_comparison(args.out, scene, cam, settings, rates, backend_of(args), args.inset, args.force, args.diff)
    print(
        f"wrote {args.out} ({cmp.image.width}x{cmp.image.height}): {len(rates)} rates x {len(settings)} modes on "
        f"background {background.describe()}"
    )
    for other in settings[1:]:
        if differ := differences(other, settings[0]):
            print(f"  {other.label} vs {settings[0].label}: {', '.join(differ)}")
    for row, prow in zip(cmp.cells, cmp.psnr):
        for cell, p in zip(row, prow):
            if p is not None and p != float("inf"):
                print(f"  {cell.settings.label:>20} {format_rate(cell.rate):>6}: PSNR {p:.2f} dB")
    if cmp.diff is not None:
        print(f"{cmp.diff.title}; colour bar -{cmp.diff.scale:.3g} .. +{cmp.diff.scale:.3g}")
        for row, prow, name in zip(cmp.cells, cmp.diff.psnr, cmp.diff.reference):
            for cell, p in zip(row, prow):
                if p != float("inf"):
                    print(f"  {cell.settings.label:>20} {format_rate(cell.rate):>6}: PSNR {p:.2f} dB vs {name}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="labelled grid of modes x sampling rates with PSNR (PNG)")
    p.add_argument("scene", type=Path)
    add_load_args(p)
    add_camera_args(p)
    p.add_argument(
        "--modes",
        default="scalar,supersample:3,gaussian_blending",
        help="comma-separated MODE[:N][+fast|+exact][+lod[:PX]] (N x N supersampling, the level-of-detail cut at PX; "
        "gaussian_blending draws its fast kernel, within 1/1024 of +exact)",
    )
    add_lod_arg(p)
    add_stochastic_args(p)
    p.add_argument("--rates", type=Rate(many=True), default="1,1/2,1/4,1/8", help="sampling rates, e.g. 1,1/2,1/4,1/8")
    add_backend_arg(p)
    p.add_argument(
        "--background",
        type=BACKGROUND,
        metavar=BACKGROUND.metavar,
        help="background colour, each in 0..1 (default black)",
    )
    p.add_argument("--inset", type=INSET, metavar=INSET.metavar, help="magnify this region (x1 pixels) in a corner")
    p.add_argument(
        "--diff",
        nargs="?",
        const="first",
        choices=list(DIFFS),
        help="add under each rate a row of signed differences (mean over RGB, colour bar below): to the "
        "first mode (--diff, --diff first) or to the dense reference, scalar 8x8 (--diff ref)",
    )
    p.add_argument("--out", required=True, help="FILE.png")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_compare)
