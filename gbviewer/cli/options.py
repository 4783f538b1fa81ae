"""What several subcommands share: camera and backend options, the camera they describe, the render-size check,
progress bars."""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

from ..core.errors import GBViewerError
from ..core.validate import integer
from ..model.camera import PROJECTIONS, Camera, load_cameras_json, orbit_camera
from ..model.camera_paths import scene_focus_depth
from ..model.scene import Scene
from ..render import AUTO, BACKEND_NAMES, RenderSettings, choose_backend
from ..render.modes import MAX_SEED, STOCHASTIC_MODES
from ..render.types import MAX_LOD
from .argtypes import MAX_SIDE, ORBIT, SIDE, Number, count

MAX_COUNT = 10_000  # most views, repeats and flicker frames of a benchmark


def add_load_args(p: argparse.ArgumentParser) -> None:
    """--primitive: how the commands that load one scene read a glTF file."""
    p.add_argument(
        "--primitive",
        type=count(lo=0),
        metavar="N",
        help="glTF: load only the N-th splat primitive (default: all of them, as one scene)",
    )


def load_options(args: argparse.Namespace) -> dict:
    """The `gbviewer.load` keywords that `add_load_args`'s options give."""
    return {"primitive": args.primitive}


def add_camera_args(p: argparse.ArgumentParser) -> None:
    """--cameras/--camera, --orbit, --width/--height, --up, --projection: shared by the commands that render."""
    p.add_argument("--cameras", type=Path, help="3DGS cameras.json")
    p.add_argument("--camera", type=count(lo=0), default=0, help="index into --cameras (default 0)")
    p.add_argument(
        "--orbit",
        type=ORBIT,
        metavar=ORBIT.metavar,
        help="orbit camera: azimuth and elevation in degrees, distance in scene units (0: auto)",
    )
    p.add_argument("--width", type=SIDE, help="image width (default 640, or the training camera's)")
    p.add_argument("--height", type=SIDE, help="image height (default 480, or the training camera's)")
    p.add_argument("--up", default="-y", choices=["-y", "+y", "+z", "-z"], help="scene up axis for orbit cameras")
    p.add_argument(
        "--projection",
        choices=PROJECTIONS,
        help="perspective (default: orbits; a --cameras entry keeps its own) or orthographic: an orbit "
        "keeps its eye with f / distance pixels per unit, a training camera is converted at the depth of "
        "the scene's centre; either way the scene appears at the same size",
    )


def add_backend_arg(p: argparse.ArgumentParser, default: str | None = AUTO, text: str = "") -> None:
    """--backend: cpu, glsl, cuda or auto."""
    p.add_argument(
        "--backend",
        default=default,
        choices=list(BACKEND_NAMES),
        help=text
        or "auto (default): CUDA where a device is usable, else GLSL on a hardware OpenGL 4.3 "
        "driver, else cpu; the choice and why go to stderr",
    )


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
        depth = scene_focus_depth(
            scene, cam, f"--projection {args.projection} on camera {args.camera}", "give an --orbit"
        )
        return cam.with_projection(args.projection, depth)
    w, h = args.width or 640, args.height or 480
    projection = args.projection or "perspective"
    if args.orbit is not None:
        az, el, dist = args.orbit
        return orbit_camera(scene, az, el, dist if dist > 0 else None, w, h, up=args.up, projection=projection)
    return orbit_camera(scene, width=w, height=h, up=args.up, projection=projection)


def add_lod_arg(p: argparse.ArgumentParser, many: bool = True) -> None:
    """--lod PX: the level-of-detail cut at PX projected pixels (gbviewer.lod); with several modes each one is
    measured or shown with and without it."""
    text = (
        "also render each mode given without its own +lod at this level of detail, beside it (MODE+lod:PX)"
        if many
        else "render the level-of-detail cut at this many projected pixels (MODE+lod:PX)"
    )
    p.add_argument("--lod", type=Number(lo=0, hi=MAX_LOD, f32=True), metavar="PX", help=text)


def with_lod(settings: list[RenderSettings], lod: float | None) -> list[RenderSettings]:
    """`settings` with each one that has no level of detail followed by its copy at `lod` pixels (None: as given),
    each spec once."""
    if lod is None:
        return settings
    out: dict[str, RenderSettings] = {}
    for s in settings:
        for t in (s, replace(s, lod=lod)) if s.lod is None else (s,):
            out.setdefault(t.spec, t)
    return list(out.values())


STOCHASTIC_OPTIONS = ("seed", "frame")  # add_stochastic_args: applied to the stochastic modes only


def add_stochastic_args(p: argparse.ArgumentParser) -> None:
    """--seed and --frame: the stochastic modes' keep decisions (RenderSettings.seed, .frame)."""
    p.add_argument(
        "--seed",
        type=count(MAX_SEED, lo=0),
        metavar="0..2^32-1",
        help="stochastic modes: the seed of the keep decisions' hash (default 0)",
    )
    p.add_argument(
        "--frame",
        type=count(MAX_SEED, lo=0),
        metavar="0..2^32-1",
        help="stochastic modes: the frame index (default 0); another index is another sample, the same "
        "seed and index the same image bit for bit",
    )


def with_stochastic(settings: list[RenderSettings], args: argparse.Namespace) -> list[RenderSettings]:
    """`settings` with the stochastic ones at --seed and --frame (those given); either given without a stochastic
    mode among `settings` is one line (it would change nothing)."""
    given = {k: v for k in STOCHASTIC_OPTIONS if (v := getattr(args, k, None)) is not None}
    if not given:
        return settings
    if not any(s.mode in STOCHASTIC_MODES for s in settings):
        option = " and ".join(f"--{k} {v}" for k, v in given.items())
        names = ", ".join(m.label for m in STOCHASTIC_MODES)
        raise GBViewerError(
            f"{option} applies to the stochastic modes ({names} and their presets); the modes "
            f"given ({', '.join(s.spec for s in settings)}) have none"
        )
    return [replace(s, **given) if s.mode in STOCHASTIC_MODES else s for s in settings]


MODE_OPTIONS = ("supersample", "sh_degree", "background")  # the options some commands have beside their modes


def settings_of(args: argparse.Namespace, default: str = "scalar", precision: str = "exact") -> list[RenderSettings]:
    """What a command renders: its --modes, or its one --mode (`default` when not given, at --lod), each parsed by
    `RenderSettings.parse` with the command's --supersample, --sh-degree and --background filling what the spec leaves
    unset (one disagreeing with the spec is one line) and gaussian_blending at `precision` unless the spec says
    '+exact' or '+fast'; --lod with --modes adds each mode's cut beside it (`with_lod`); --seed and --frame set the
    stochastic ones (`with_stochastic`). The one way every command reads its modes."""
    fill = {key: getattr(args, key, None) for key in MODE_OPTIONS}
    if hasattr(args, "modes"):
        parsed = RenderSettings.parse_list(args.modes, default_precision=precision, **fill)
        parsed = with_lod(parsed, getattr(args, "lod", None))
    else:
        parsed = [RenderSettings.parse(args.mode or default, default_precision=precision, lod=args.lod, **fill)]
    return with_stochastic(parsed, args)


def path_args(args: argparse.Namespace, paths: tuple[str, ...], pane: tuple[int, int]) -> None:
    """A path command's --size into args.width/height (`pane` when no size, width, height or cameras are given), and
    its --path checked: one of `paths` or a keyframes file."""
    if args.size:
        args.width, args.height = args.size
    elif not (args.width or args.height or args.cameras):
        args.width, args.height = pane
    if args.path not in paths and not Path(args.path).is_file():
        raise GBViewerError(
            f"--path {args.path}: expected {', '.join(paths)} or a keyframes FILE.json, got "
            f"{'a folder' if Path(args.path).is_dir() else 'no such file'}"
        )


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


def check_inset(inset: tuple[float, float, float, float] | None, width: int, height: int) -> None:
    """Refuse an --inset region X,Y,W,H that does not lie inside the width x height (x1) image."""
    if inset is not None:
        x, y, w, h = inset
        if x < 0 or y < 0 or x + w > width or y + h > height:
            raise GBViewerError(
                f"--inset {x:g},{y:g},{w:g},{h:g}: expected a region inside the {width}x{height} "
                f"x1 image (X >= 0, Y >= 0, X+W <= {width}, Y+H <= {height})"
            )


def progress_columns() -> tuple:
    """A rich progress bar with percentage, elapsed time and ETA."""
    from rich.progress import BarColumn, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return (
        TextColumn("{task.description}"),
        BarColumn(),
        TaskProgressColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
    )


@contextmanager
def progress_bar(name: str, total: float):
    """A transient progress bar (percentage, elapsed, ETA) of `total` units; yields advance(units)."""
    from rich.progress import Progress

    with Progress(*progress_columns(), transient=True) as progress:
        task = progress.add_task(name, total=total)
        yield lambda units: progress.advance(task, units)
