"""The `gbviewer` command line: info, render, demo (the main job), bench, eval, video, compare."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

from . import DEFAULT_SCENE
from .argtypes import BACKGROUND, INSET, MAX_SIDE, ORBIT, PIXEL, SIDE, SIZE, Number, Parser, Rate, count, positive
from .camera import PROJECTIONS, Camera, format_rate, load_cameras_json, orbit_camera, parse_rates
from .camera_paths import MAX_FRAMES, PATHS, camera_path, scene_focus_depth, zoom_path
from .errors import GBViewerError
from .eval.options import add_dataset_args, add_eval_args, scene_pairs
from .figure import DIFFS, compose_grid, render_grid, save_image, write_comparison
from .io import load, write_inria_ply
from .io.files import check_writable
from .io.outputs import refuse_collisions, refuse_inputs
from .render import AUTO, BACKEND_NAMES, Mode, RenderSettings, choose_backend, get_renderer, trace_pixel
from .render.budget import BUDGET_ENV
from .scene import Scene
from .validate import integer
from .video import MAX_FPS, MIN_FPS, record_video


def add_camera_args(p: argparse.ArgumentParser) -> None:
    """--cameras/--camera, --orbit, --width/--height, --up, --projection: shared by the commands that render."""
    p.add_argument("--cameras", type=Path, help="3DGS cameras.json")
    p.add_argument("--camera", type=count(lo=0), default=0, help="index into --cameras (default 0)")
    p.add_argument("--orbit", type=ORBIT, metavar=ORBIT.metavar,
                   help="orbit camera: azimuth and elevation in degrees, distance in scene units (0: auto)")
    p.add_argument("--width", type=SIDE, help="image width (default 640, or the training camera's)")
    p.add_argument("--height", type=SIDE, help="image height (default 480, or the training camera's)")
    p.add_argument("--up", default="-y", choices=["-y", "+y", "+z", "-z"], help="scene up axis for orbit cameras")
    p.add_argument("--projection", choices=PROJECTIONS,
                   help="perspective (default: orbits; a --cameras entry keeps its own) or orthographic: an orbit "
                   "keeps its eye with f / distance pixels per unit, a training camera is converted at the depth of "
                   "the scene's centre; either way the scene appears at the same size")


def add_backend_arg(p: argparse.ArgumentParser, default: str | None = AUTO, text: str = "") -> None:
    """--backend: cpu, glsl, cuda or auto."""
    p.add_argument("--backend", default=default, choices=list(BACKEND_NAMES),
                   help=text or "auto (default): CUDA where a device is usable, else GLSL on a hardware OpenGL 4.3 "
                   "driver, else cpu; the choice and why go to stderr")


def camera_from_args(scene: Scene, args: argparse.Namespace) -> Camera:
    """The camera the arguments describe: a training camera, an orbit, or the default framing, with --projection."""
    if args.cameras is not None:
        cams = load_cameras_json(args.cameras)
        if not 0 <= args.camera < len(cams):
            raise GBViewerError(f"{args.cameras}: camera {args.camera} out of range (0..{len(cams) - 1})")
        cam = cams[args.camera]
        if args.width or args.height:
            w = args.width or round(cam.width * args.height / cam.height)
            h = args.height or round(cam.height * args.width / cam.width)
            cam = cam.with_size(w, h)
        if args.projection in (None, cam.projection):
            return cam
        depth = scene_focus_depth(scene, cam, f"--projection {args.projection} on camera {args.camera}",
                                  "give an --orbit")
        return cam.with_projection(args.projection, depth)
    w, h = args.width or 640, args.height or 480
    projection = args.projection or "perspective"
    if args.orbit is not None:
        az, el, dist = args.orbit
        return orbit_camera(scene, az, el, dist if dist > 0 else None, w, h, up=args.up, projection=projection)
    return orbit_camera(scene, width=w, height=h, up=args.up, projection=projection)


def backend_of(args: argparse.Namespace) -> str:
    """The backend --backend names; for auto (the default) the one `choose_backend()` picks, said once on stderr."""
    if args.backend in (None, AUTO):
        picked = choose_backend()
        print(f"gbviewer: backend {picked}", file=sys.stderr)
        args.backend = picked.name
    return args.backend


def check_render_size(width: int, height: int, rates: list[float], option: str) -> None:
    """Refuse, before anything is allocated, a render of width x height at the largest of `rates` with a side
    over MAX_SIDE."""
    side = max(width, height) * max(rates)
    integer(round(side), f"{option}: image side rendered at x{max(rates):g}", hi=MAX_SIDE)


def cmd_info(args: argparse.Namespace) -> int:
    scene = load(args.scene)
    lo, hi = scene.bounds
    rlo, rhi = scene.robust_bounds()
    info = {
        "file": str(args.scene),
        "format": scene.meta.get("format"),
        "version": scene.meta.get("version"),
        "splats": scene.num_splats,
        "sh_degree": scene.sh_degree,
        "filter_3D": scene.filter_3d is not None,
        "bounds": [lo.tolist(), hi.tolist()],
        "robust_bounds_2_98": [rlo.tolist(), rhi.tolist()],
        "properties": scene.meta.get("properties", []),
    }
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        for key, val in info.items():
            if key == "properties":
                val = ", ".join(val) if len(val) <= 20 else ", ".join(val[:18]) + f", ... ({len(val)} in all)"
            print(f"{key:>20}: {val}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".ply":
        raise GBViewerError(f"{out}: output must end in .ply (a standard INRIA 3DGS ply)")
    check_writable(out, args.force, inputs=[args.scene])
    scene = load(args.scene)
    write_inria_ply(scene, out, force=args.force)
    print(f"{out}: {scene.num_splats} splats, SH degree {scene.sh_degree}, from {scene.meta.get('format')} "
          f"(version {scene.meta.get('version')})")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".npy"):
        raise GBViewerError(f"{out}: output must end in .png or .npy")
    check_writable(out, args.force, inputs=[args.scene, args.cameras])
    scene = load(args.scene)
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, [args.scale], "--scale")
    cam = cam.at_sampling_rate(args.scale)
    settings = RenderSettings(Mode.parse(args.mode), args.supersample, args.background, args.sh_degree)
    frame = get_renderer(scene, backend_of(args)).render(cam, settings)
    save_image(out, frame.rgb, force=args.force)
    st = frame.stats
    print(f"{out}: {cam.width}x{cam.height} {settings.label} on {args.backend}: {st.total_ms:.1f} ms "
          f"(preprocess {st.preprocess_ms:.1f}, sort {st.sort_ms:.1f}, blend {st.blend_ms:.1f}), "
          f"{st.visible} visible splats, {st.evals_per_pixel:.1f} evaluations/pixel")
    return 0


DEMO_VIDEO_FRAMES = 36  # 3 s at 12 fps
DEMO_FILES = ("comparison.png", "zoom.mp4")  # what demo writes into --out
DEMO_SETTINGS = [RenderSettings(Mode.SCALAR), RenderSettings(Mode.SCALAR, supersample=3),
                 RenderSettings(Mode.GAUSSIAN_BLENDING)]


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job without a window: side-by-side comparison of the bundled (or given) scene at x1 and x1/8, and
    a short x1 -> x1/8 zoom video of the same modes."""
    from rich.progress import Progress

    scene_path = args.scene or DEFAULT_SCENE
    out_dir, force, args.cameras = Path(args.out), getattr(args, "force", False), getattr(args, "cameras", None)
    for name in DEMO_FILES:
        check_writable(out_dir / name, force, inputs=[scene_path, args.cameras])
    scene = load(scene_path)
    cam = camera_from_args(scene, args)
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print("no display found: writing the comparison images instead of opening a window")
    cells = render_grid(scene, cam, DEMO_SETTINGS, [1.0, 1.0 / 8.0], backend_of(args))
    img = compose_grid(cells, cam.width, cam.height)
    path = save_image(out_dir / DEMO_FILES[0], img, force=force)
    print(f"wrote {path} ({img.width}x{img.height}): {Path(scene_path).name}, "
          + ", ".join(f"{c.settings.label} {c.total_ms:.0f} ms" for c in cells[0]))
    small = cam.with_size(max(2, cam.width // 2), max(2, cam.height // 2))  # half size keeps it quick
    frames = zoom_path(small, DEMO_VIDEO_FRAMES)
    with Progress(transient=True) as progress:
        task = progress.add_task("zoom video", total=len(frames))
        info = record_video(scene, frames, DEMO_SETTINGS, out_dir / DEMO_FILES[1], fps=12, backend=args.backend,
                            force=force, progress=lambda done, total: progress.update(task, completed=done))
    print(f"wrote {info.path} ({len(frames)} frames, x1 -> x1/8, {' | '.join(s.label for s in DEMO_SETTINGS)})")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """`gbviewer [SCENE] [--data DATASET]`: the desktop viewer (with the dataset's photos); without a display, say so
    and write the comparison instead."""
    from .app import has_display_env, open_window

    for path, what in ((args.scene, ""), (args.data, "--data ")):
        if path is not None and not path.exists():
            raise GBViewerError(f"{what}{path}: no such file or folder")
    opened, why = open_window(args.scene, args.cameras, projection=args.projection, backend=args.backend,
                              data=args.data, images=args.images)
    if opened:
        return 0
    if has_display_env()[0]:  # (without one, demo says so itself)
        print(f"cannot open the viewer window: {why}; writing the comparison images instead")
    return cmd_demo(args)


MAX_COUNT = 10_000  # most views, repeats and flicker frames of a benchmark
BENCH_DEFAULTS = {"modes": "scalar,gaussian_blending,supersample:3", "rates": "1,1/8", "views": 2, "repeat": 2,
                  "simd": None}
BENCH_FULL = {"modes": "scalar,mip,analytic,gaussian_blending,supersample:3", "rates": "4,2,1,1/2,1/4,1/8",
              "views": 3, "repeat": 3, "simd": "all"}


def progress_columns() -> tuple:
    """A rich progress bar with percentage, elapsed time and ETA."""
    from rich.progress import BarColumn, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return (TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(), TimeElapsedColumn(),
            TextColumn("eta"), TimeRemainingColumn())


def resolve_bench_options(args: argparse.Namespace) -> argparse.Namespace:
    """Fill --modes, --rates (parsed), --views, --repeat and --simd left out from BENCH_FULL (--full) or
    BENCH_DEFAULTS."""
    preset = BENCH_FULL if args.full else BENCH_DEFAULTS
    for key, value in preset.items():
        if getattr(args, key) is None:
            setattr(args, key, parse_rates(value) if key == "rates" else value)
    return args


@contextmanager
def progress_bar(name: str, total: float):
    """A transient progress bar (percentage, elapsed, ETA) of `total` units; yields advance(units)."""
    from rich.progress import Progress

    with Progress(*progress_columns(), transient=True) as progress:
        task = progress.add_task(name, total=total)
        yield lambda units: progress.advance(task, units)


def cmd_bench(args: argparse.Namespace) -> int:
    """Speed (per SIMD path of the CPU backend) and zoom fidelity per scene, mode, backend and rate; tables, JSON,
    plots."""
    from . import bench

    simd_given = args.simd is not None
    resolve_bench_options(args)
    backends, unavailable = bench.select_backends(args.backends.split(","))
    for b, why in unavailable.items():
        print(f"skipping backend {b}: {why}")
    if simd_given and "cpu" not in backends:
        raise GBViewerError("--simd chooses the cpu backend's paths; --backends has no cpu")
    check_render_size(*args.size, args.rates, "--rates")
    outputs = [Path(args.json)] if args.json else []
    if args.plots:
        outputs += [bench.plot_path(Path(args.plots), Path(s).name) for s in args.scenes]
    refuse_collisions(outputs)
    refuse_inputs(outputs, [*args.scenes, args.cameras])

    result = bench.run_bench(
        args.scenes, RenderSettings.parse_list(args.modes), args.rates, backends, views=args.views,
        size=args.size, repeat=args.repeat, cameras=args.cameras, up=args.up, simd=args.simd,
        flicker_frames=args.flicker_frames, flicker_step=args.flicker_step,
        outputs=outputs, force=args.force, progress=progress_bar)
    bench.print_tables(result.speed, result.fidelity, result.simd)
    if result.oit:
        bench.print_oit(result.oit)
    if args.json:
        path = bench.write_json(Path(args.json), result.speed, result.fidelity, args.force, oit=result.oit,
                                simd=result.simd)
        print(f"wrote {path}")
    if args.plots:
        for p in bench.write_plots(Path(args.plots), result.speed, result.fidelity, args.force):
            print(f"wrote {p}")
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    """PSNR and SSIM of every mode at every rate against the training photos (the paper's tables)."""
    from . import eval as evaluation

    pairs = scene_pairs(args.scenes, args.data)
    outputs = [args.json] * bool(args.json) + (evaluation.plot_paths(args.plots, pairs) if args.plots else [])
    refuse_collisions(outputs)
    for path in outputs:
        check_writable(path, args.force, inputs=[p for pair in pairs for p in pair])
    result = evaluation.run_eval(
        pairs, RenderSettings.parse_list(args.modes), args.rates, split=args.split, background=args.background,
        images=args.images, backend=args.backend, workers=args.workers, ray=args.ray, threads=args.threads,
        cache=args.cache or evaluation.default_cache(), progress=progress_bar)
    evaluation.print_tables(result)
    if args.json:
        print(f"wrote {evaluation.write_json(args.json, result, args.force)}")
    if args.plots:
        for path in evaluation.write_plots(args.plots, result, args.force):
            print(f"wrote {path}")
    return 0


VIDEO_PANE = (480, 360)  # default pane size of `gbviewer video`


def cmd_video(args: argparse.Namespace) -> int:
    """Side-by-side zoom video of several modes (H.264 MP4)."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    settings = RenderSettings.parse_list(args.modes)
    if args.size:
        args.width, args.height = args.size
    elif not (args.width or args.height or args.cameras):
        args.width, args.height = VIDEO_PANE
    check_writable(args.out, args.force, inputs=[args.scene, args.cameras, None if args.path in PATHS else args.path])
    scene = load(args.scene)
    cam = camera_from_args(scene, args)
    if args.path == "rate":
        check_render_size(cam.width, cam.height, [args.from_rate, args.to_rate], "--from/--to")
    path = camera_path(args.path, cam, args.frames, args.from_rate, args.to_rate, scene, args.up, fps=args.fps,
                       seconds=args.seconds, max_frames=args.max_frames)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("frames"),
               TimeElapsedColumn(), TextColumn("eta"), TimeRemainingColumn())
    backend = backend_of(args)
    with Progress(*columns) as progress:
        task = progress.add_task(f"{Path(args.out).name}", total=len(path))
        info = record_video(scene, path, settings, args.out, fps=args.fps, backend=backend, inset=args.inset,
                            crf=args.crf, force=args.force,
                            progress=lambda done, total: progress.update(task, completed=done))
    print(f"wrote {info.path}: {info.frames} frames of {info.width}x{info.height} at {info.fps:g} fps "
          f"({info.frames / info.fps:.1f} s), {', '.join(s.label for s in settings)}, {args.path} "
          f"{f'{args.from_rate:g} -> {args.to_rate:g} ' if args.path in PATHS else ''}"
          f"in {info.elapsed_s:.1f} s")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """Labelled grid of modes x sampling rates with PSNR under each cell."""
    settings = RenderSettings.parse_list(args.modes)
    rates = args.rates
    check_writable(args.out, args.force, inputs=[args.scene, args.cameras])
    scene = load(args.scene)
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, rates, "--rates")
    cmp = write_comparison(args.out, scene, cam, settings, rates, backend_of(args), args.inset, args.force,
                           args.diff)
    print(f"wrote {args.out} ({cmp.image.width}x{cmp.image.height}): {len(rates)} rates x {len(settings)} modes")
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


def cmd_trace(args: argparse.Namespace) -> int:
    """Pixel traces of the CPU kernel, one rich table per mode; --json writes them all."""
    from .trace_report import print_traces, write_traces

    if args.json:
        check_writable(args.json, args.force, inputs=[args.scene, args.cameras])
    settings = RenderSettings.parse_list(args.modes, background=args.background)
    if args.supersample is not None:
        settings = [s if s.supersample > 1 else replace(s, supersample=args.supersample) for s in settings]
    scene = load(args.scene)
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, [args.scale], "--scale")
    cam = cam.at_sampling_rate(args.scale)
    x, y = args.pixel
    if x >= cam.width or y >= cam.height:
        raise GBViewerError(f"--pixel {x},{y}: outside the {cam.width}x{cam.height} image at --scale "
                            f"{args.scale:g} (x in 0..{cam.width - 1}, y in 0..{cam.height - 1})")
    traces = [trace_pixel(scene, cam, x, y, s.mode, s.supersample, s.background) for s in settings]
    print_traces(traces, args.top)
    if args.json:
        print(f"wrote {write_traces(Path(args.json), traces, str(args.scene), args.force)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="gbviewer", description=__doc__)
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = parser.add_subparsers(dest="command")

    p = sub.add_parser("info", help="describe a scene file")
    p.add_argument("scene", type=Path)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="write any supported scene as a standard INRIA 3DGS .ply")
    p.add_argument("scene", type=Path)
    p.add_argument("out", type=Path, help="OUT.ply")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("render", help="render one image")
    p.add_argument("scene", type=Path)
    add_camera_args(p)
    p.add_argument("--mode", default="scalar", choices=[m.label for m in Mode])
    p.add_argument("--supersample", type=count(8), default=1, metavar="1..8")
    p.add_argument("--scale", type=Rate(), default=1.0, help="sampling rate: 8, 1, 0.125 or 1/8")
    add_backend_arg(p)
    p.add_argument("--background", type=BACKGROUND, default=(0.0, 0.0, 0.0), metavar=BACKGROUND.metavar,
                   help="background colour, each in 0..1")
    p.add_argument("--sh-degree", type=count(3, lo=0), default=3, metavar="0..3")
    p.add_argument("--out", required=True, help="FILE.png or FILE.npy (float32 RGB)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("view", help="open the desktop viewer (what `gbviewer [SCENE]` runs); without a display, "
                                    "write the comparison images like demo")
    p.add_argument("scene", type=Path, nargs="?")
    add_camera_args(p)
    add_backend_arg(p, None, "the viewer's backend, as its panel sets it (default: the one it saved, auto at first), "
                    "and that of the no-display fallback (default auto)")
    add_dataset_args(p)
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

    p = sub.add_parser("bench", help="speed (per SIMD path of the CPU backend) and zoom fidelity per mode, backend "
                                     "and sampling rate")
    p.add_argument("scenes", type=Path, nargs="+")
    p.add_argument("--full", action="store_true",
                   help=f"the full sweep (long: x4 renders 16x the pixels of x1): --modes {BENCH_FULL['modes']} "
                   f"--rates {BENCH_FULL['rates']} --views {BENCH_FULL['views']} --repeat {BENCH_FULL['repeat']} "
                   f"--simd {BENCH_FULL['simd']}; options given explicitly win")
    p.add_argument("--modes", help="comma-separated MODE or MODE:N (N x N supersampling; supersample:N = scalar:N); "
                   "with wsr or duplex the sort length, cells, PSNR vs scalar and flicker are measured too "
                   f"(default {BENCH_DEFAULTS['modes']})")
    p.add_argument("--backends", default="cpu")
    p.add_argument("--rates", type=Rate(many=True),
                   help=f"sampling rates, e.g. 8,4,2,1,1/2,1/4,1/8 (default {BENCH_DEFAULTS['rates']})")
    p.add_argument("--simd", help="the cpu backend's SIMD paths to measure, each in the same run (scalar, avx2, "
                   "avx512; all: every path this CPU runs; current: the one in use, GBVIEWER_SIMD or the best); "
                   "default: scalar and the one in use. Fidelity is measured on the one in use")
    p.add_argument("--views", type=count(MAX_COUNT), help=f"views per scene (orbit, or spread over --cameras; default "
                   f"{BENCH_DEFAULTS['views']})")
    p.add_argument("--cameras", type=Path, help="3DGS cameras.json: use training views")
    p.add_argument("--up", default="-y", choices=["-y", "+y", "+z", "-z"])
    p.add_argument("--size", type=SIZE, default=(640, 480), metavar="WxH", help="x1 image size (default 640x480)")
    p.add_argument("--repeat", type=count(MAX_COUNT), help="timed renders per view and SIMD path, after one warm-up "
                   f"per mode, rate and path (default {BENCH_DEFAULTS['repeat']})")
    p.add_argument("--json", help="write every number and the machine description here")
    p.add_argument("--plots", help="write PNG plots into this folder")
    p.add_argument("--force", action="store_true", help="overwrite existing --json/--plots files")
    p.add_argument("--flicker-frames", type=count(MAX_COUNT), default=16,
                   help="with wsr or duplex among --modes: frames of the slow orbit that measures popping")
    p.add_argument("--flicker-step", type=positive(360.0), default=0.1,
                   help="degrees of azimuth between those frames")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("eval", help="PSNR and SSIM of every mode and sampling rate against a scene's training "
                                    "photos (COLMAP, Blender or cameras.json datasets), the paper's tables")
    add_eval_args(p)
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("video", help="side-by-side zoom video of several modes (H.264 MP4)")
    p.add_argument("scene", type=Path)
    add_camera_args(p)
    p.add_argument("--modes", default="scalar,supersample:3,gaussian_blending",
                   help="comma-separated MODE or MODE:N (N x N supersampling; supersample:N = scalar:N)")
    p.add_argument("--path", default="zoom",
                   help="zoom (focal length), dolly (camera along its axis), rate (same view, rendered at the rate "
                   "and nearest-upscaled) or a keyframes FILE.json (see gbviewer.keyframes.load_keyframes)")
    p.add_argument("--from", dest="from_rate", type=Rate(), default=1.0, help="first sampling rate (default 1)")
    p.add_argument("--to", dest="to_rate", type=Rate(), default=1.0 / 8.0, help="last sampling rate (default 1/8)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--frames", type=count(), help="number of frames")
    length.add_argument("--seconds", type=positive(), help="length in seconds (default 4, or the keyframes' span)")
    p.add_argument("--fps", type=Number(lo=MIN_FPS, hi=MAX_FPS), default=30.0,
                   help=f"frames per second, {MIN_FPS:g}..{MAX_FPS:g} (default 30)")
    p.add_argument("--max-frames", type=count(), default=MAX_FRAMES,
                   help=f"refuse videos longer than this many frames (default {MAX_FRAMES})")
    p.add_argument("--size", type=SIZE, metavar="WxH", help="size of each pane (default 480x360)")
    add_backend_arg(p)
    p.add_argument("--inset", type=INSET, metavar=INSET.metavar, help="magnify this region (x1 pixels) in a corner")
    p.add_argument("--crf", type=count(51, lo=0), default=18, metavar="0..51",
                   help="H.264 constant rate factor (0 lossless, 18 default, 23 ffmpeg's default)")
    p.add_argument("--out", required=True, help="FILE.mp4")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_video)

    p = sub.add_parser("trace", help="what the CPU kernel did at one pixel, splat by splat, per mode: top "
                                     "contributors, rejections, colour and transmittance (tables; --json)")
    p.add_argument("scene", type=Path)
    add_camera_args(p)
    p.add_argument("--pixel", type=PIXEL, required=True, metavar=PIXEL.metavar,
                   help="the output pixel, from 0 (x right, y down) in the image at --scale")
    p.add_argument("--modes", default="scalar,gaussian_blending",
                   help="comma-separated MODE or MODE:N (N x N supersampling; supersample:N = scalar:N)")
    p.add_argument("--supersample", type=count(8), metavar="1..8", help="N x N samples for the modes given without :N")
    p.add_argument("--scale", type=Rate(), default=1.0, help="sampling rate: 8, 1, 0.125 or 1/8")
    p.add_argument("--background", type=BACKGROUND, default=(0.0, 0.0, 0.0), metavar=BACKGROUND.metavar,
                   help="background colour, each in 0..1")
    p.add_argument("--top", type=count(MAX_COUNT), default=10, help="contributors shown per mode (default 10)")
    p.add_argument("--json", help="write every trace here (FILE.json; see gbviewer.PixelTrace.to_json)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    p.set_defaults(func=cmd_trace)

    p = sub.add_parser("compare", help="labelled grid of modes x sampling rates with PSNR (PNG)")
    p.add_argument("scene", type=Path)
    add_camera_args(p)
    p.add_argument("--modes", default="scalar,supersample:3,gaussian_blending")
    p.add_argument("--rates", type=Rate(many=True), default="1,1/2,1/4,1/8",
                   help="sampling rates, e.g. 1,1/2,1/4,1/8")
    add_backend_arg(p)
    p.add_argument("--inset", type=INSET, metavar=INSET.metavar, help="magnify this region (x1 pixels) in a corner")
    p.add_argument("--diff", nargs="?", const="first", choices=list(DIFFS),
                   help="add under each rate a row of signed differences (mean over RGB, colour bar below): to the "
                        "first mode (--diff, --diff first) or to the dense reference, scalar 8x8 (--diff ref)")
    p.add_argument("--out", required=True, help="FILE.png")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_compare)
    return parser


def _join_signed_values(argv: list[str]) -> list[str]:
    """'--up -y' -> '--up=-y': argparse would take '-y' for an option."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1] == "--up" and arg in ("-y", "-z", "+y", "+z"):
            out[-1] = f"--up={arg}"
        else:
            out.append(arg)
    return out


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised like Ctrl-C's KeyboardInterrupt so that every `finally` (temporary files, ffmpeg)
    runs before the process exits with 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextmanager
def _signals_interrupt():
    """While the command runs (in the main thread), SIGTERM and SIGHUP raise `Terminated`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise Terminated(signum)

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _quiet_stdout() -> None:
    """stdout's reader went away (`gbviewer info ... | head -1`): send what is left to /dev/null so that Python's
    final flush does not complain (the recipe of the `signal` module's documentation)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit status: 0, 2 for bad input (one line on stderr), 128 + N for signal N
    (SIGINT, SIGTERM, SIGHUP; SIGPIPE when stdout is closed early)."""
    parser = build_parser()
    argv = _join_signed_values(sys.argv[1:] if argv is None else argv)
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    first = next((a for a in argv if a != "--debug"), None)
    if first is None or (first not in commands and first not in ("-h", "--help")):
        argv = ["view", *argv] if first is None else [*argv[:argv.index(first)], "view", *argv[argv.index(first):]]
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # named by the command's own parser, whose --help lists what it takes
            commands[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as exc:  # --help, or a usage error already printed in one line
        return int(exc.code or 0)
    try:
        with _signals_interrupt():
            status = args.func(args)
            sys.stdout.flush()
        return status
    except BrokenPipeError:
        _quiet_stdout()
        return 128 + signal.SIGPIPE
    except (GBViewerError, OSError) as exc:
        if args.debug:
            raise
        print(f"gbviewer: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError as exc:  # beyond the estimate render.budget refuses before a frame (e.g. long tile lists)
        if args.debug:
            raise
        print(f"gbviewer: error: out of memory ({exc or 'MemoryError'}); render smaller, or see {BUDGET_ENV}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
        print(f"gbviewer: interrupted ({signal.Signals(signum).name})", file=sys.stderr)
        return 128 + signum


if __name__ == "__main__":
    sys.exit(main())
