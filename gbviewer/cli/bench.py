"""`gbviewer bench`: speed and zoom fidelity per scene, mode, backend and rate."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.errors import GBViewerError
from ..core.extras import require
from ..core.outputs import refuse_collisions, refuse_inputs
from ..model.camera import parse_rates
from ..render import BACKENDS
from .argtypes import SIZE, Rate, count, positive
from .options import MAX_COUNT, add_lod_arg, add_stochastic_args, check_render_size, progress_bar, settings_of

BENCH_DEFAULTS = {
    "modes": "scalar,gaussian_blending,gaussian_blending+fast,supersample:3",
    "rates": "1,1/8",
    "views": 2,
    "repeat": 2,
    "simd": None,
}
BENCH_FULL = {
    "modes": "scalar,mip,analytic,gaussian_blending,gaussian_blending+fast,supersample:3",
    "rates": "4,2,1,1/2,1/4,1/8",
    "views": 3,
    "repeat": 3,
    "simd": "all",
}


def resolve_bench_options(args: argparse.Namespace) -> argparse.Namespace:
    """Fill --modes, --rates (parsed), --views, --repeat and --simd left out from BENCH_FULL (--full) or
    BENCH_DEFAULTS."""
    preset = BENCH_FULL if args.full else BENCH_DEFAULTS
    for key, value in preset.items():
        if getattr(args, key) is None:
            setattr(args, key, parse_rates(value) if key == "rates" else value)
    return args


def cmd_bench(args: argparse.Namespace) -> int:
    """Speed (per SIMD path of the CPU backend) and zoom fidelity per scene, mode, backend and rate; tables, JSON,
    plots."""
    from .. import bench

    if args.plots:
        require("eval", "matplotlib", "--plots", load=False)
    simd_given = args.simd is not None
    resolve_bench_options(args)
    backends, unavailable = bench.select_backends(args.backends.split(","))
    for b, why in unavailable.items():
        print(f"skipping backend {b}: {why}")
    if simd_given and not any(BACKENDS[b].capabilities.simd for b in backends):
        raise GBViewerError("--simd chooses the SIMD paths of the cpu backend; --backends has no backend with them")
    check_render_size(*args.size, args.rates, "--rates")
    outputs = [Path(args.json)] if args.json else []
    if args.plots:
        outputs += [bench.plot_path(Path(args.plots), Path(s).name) for s in args.scenes]
    refuse_collisions(outputs)
    refuse_inputs(outputs, [*args.scenes, args.cameras])

    result = bench.run_bench(
        args.scenes,
        settings_of(args),
        args.rates,
        backends,
        views=args.views,
        size=args.size,
        repeat=args.repeat,
        cameras=args.cameras,
        up=args.up,
        simd=args.simd,
        flicker_frames=args.flicker_frames,
        flicker_step=args.flicker_step,
        flicker_pairs=args.flicker_pairs,
        flicker_size=args.flicker_size,
        outputs=outputs,
        force=args.force,
        progress=progress_bar,
    )
    bench.print_tables(result.speed, result.fidelity, result.simd)
    if result.flicker:
        bench.print_flicker(result.flicker)
    if result.oit:
        bench.print_oit(result.oit)
    if args.json:
        path = bench.write_json(
            Path(args.json),
            result.speed,
            result.fidelity,
            args.force,
            oit=result.oit,
            simd=result.simd,
            flicker=result.flicker,
        )
        print(f"wrote {path}")
    if args.plots:
        for p in bench.write_plots(Path(args.plots), result.speed, result.fidelity, args.force):
            print(f"wrote {p}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench", help="speed (per SIMD path of the CPU backend) and zoom fidelity per mode, backend and sampling rate"
    )
    p.add_argument("scenes", type=Path, nargs="+")
    p.add_argument(
        "--full",
        action="store_true",
        help=f"the full sweep (long: x4 renders 16x the pixels of x1): --modes {BENCH_FULL['modes']} "
        f"--rates {BENCH_FULL['rates']} --views {BENCH_FULL['views']} --repeat {BENCH_FULL['repeat']} "
        f"--simd {BENCH_FULL['simd']}; options given explicitly win",
    )
    p.add_argument(
        "--modes",
        help="comma-separated MODE[:N][+lod[:PX]] (N x N supersampling, supersample:N = "
        "scalar:N; the level-of-detail cut at PX); "
        "with wsr or duplex the sort length, cells, PSNR vs scalar and flicker are measured too "
        f"(default {BENCH_DEFAULTS['modes']})",
    )
    add_lod_arg(p)
    add_stochastic_args(p)
    p.add_argument("--backends", default="cpu")
    p.add_argument(
        "--rates",
        type=Rate(many=True),
        help=f"sampling rates, e.g. 8,4,2,1,1/2,1/4,1/8 (default {BENCH_DEFAULTS['rates']})",
    )
    p.add_argument(
        "--simd",
        help="the cpu backend's SIMD paths to measure, each in the same run (scalar, avx2, "
        "avx512; all: every path this CPU runs; current: the one in use, GBVIEWER_SIMD or the best); "
        "default: scalar and the one in use. Fidelity is measured on the one in use",
    )
    p.add_argument(
        "--views",
        type=count(MAX_COUNT),
        help=f"views per scene (orbit, or spread over --cameras; default {BENCH_DEFAULTS['views']})",
    )
    p.add_argument("--cameras", type=Path, help="3DGS cameras.json: use training views")
    p.add_argument("--up", default="-y", choices=["-y", "+y", "+z", "-z"])
    p.add_argument("--size", type=SIZE, default=(640, 480), metavar="WxH", help="x1 image size (default 640x480)")
    p.add_argument(
        "--repeat",
        type=count(MAX_COUNT),
        help="timed renders per view and SIMD path, after one warm-up "
        f"per mode, rate and path (default {BENCH_DEFAULTS['repeat']})",
    )
    p.add_argument("--json", help="write every number and the machine description here")
    p.add_argument("--plots", help="write PNG plots into this folder")
    p.add_argument("--force", action="store_true", help="overwrite existing --json/--plots files")
    p.add_argument(
        "--flicker-pairs",
        type=count(MAX_COUNT, lo=0),
        default=3,
        help="pairs of frames of the zoom x1 -> x1/4 on which every mode's flicker is measured against "
        "scalar 8x8 (gbviewer flicker; default 3; 0: no flicker measure)",
    )
    p.add_argument(
        "--flicker-size",
        type=SIZE,
        default=(160, 120),
        metavar="WxH",
        help="image size of that measure (default 160x120)",
    )
    p.add_argument(
        "--flicker-frames",
        type=count(MAX_COUNT),
        default=16,
        help="with wsr or duplex among --modes: frames of the slow orbit that measures popping",
    )
    p.add_argument("--flicker-step", type=positive(360.0), default=0.1, help="degrees of azimuth between those frames")
    p.set_defaults(func=cmd_bench)
