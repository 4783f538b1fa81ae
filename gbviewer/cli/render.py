"""`gbviewer render`: one image."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.errors import GBViewerError, RenderError
from ..core.files import check_writable
from ..io import load
from ..io.trained_as import describe
from ..outputs.figure import save_image
from ..render import Mode, get_renderer
from ..render.presets import PRESETS, trained_spec
from ..render.tiles import render_tiled
from .argtypes import BACKGROUND, Rate, count
from .options import (
    add_backend_arg,
    add_camera_args,
    add_load_args,
    add_lod_arg,
    add_stochastic_args,
    backend_of,
    camera_from_args,
    check_render_size,
    load_options,
    progress_columns,
    settings_of,
)


def cmd_render(args: argparse.Namespace) -> int:
    """One image; beyond the memory budget the CPU backend renders it in parts (`render_tiled`), bit for bit."""
    from rich.progress import Progress

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".npy"):
        raise GBViewerError(f"{out}: output must end in .png or .npy")
    check_writable(out, args.force, inputs=[args.scene, args.cameras], option="--out")
    scene = load(args.scene, **load_options(args))
    cam = camera_from_args(scene, args)
    check_render_size(cam.width, cam.height, [args.scale], "--scale")
    cam = cam.at_sampling_rate(args.scale)
    trained = trained_spec(scene.meta)
    try:
        settings = settings_of(args, trained or "scalar", precision="fast")[0]
    except RenderError as exc:  # an option against the file's mode, which the user did not give
        if args.mode is not None or not trained:
            raise
        raise RenderError(
            f"{exc}: {args.scene} says it was trained as {describe(scene.meta)}, so it renders as "
            f"{trained} unless --mode says otherwise"
        ) from None
    renderer = get_renderer(scene, backend_of(args))
    with Progress(*progress_columns(), transient=True) as bar:  # shown while a large frame renders in parts
        task = bar.add_task("parts", total=None, visible=False)
        frame = render_tiled(
            renderer,
            cam,
            settings,
            scene.num_splats,
            progress=lambda done, total: bar.update(task, completed=done, total=total, visible=True),
        )
    save_image(out, frame.rgb, force=args.force)
    st = frame.stats
    how = f" (as trained: {describe(scene.meta)})" if args.mode is None and trained else ""
    print(
        f"{out}: {cam.width}x{cam.height} {settings.label}{how} on {args.backend}: {st.total_ms:.1f} ms "
        f"(preprocess {st.preprocess_ms:.1f}, sort {st.sort_ms:.1f}, blend {st.blend_ms:.1f}), "
        f"{st.visible} visible splats, {st.evals_per_pixel:.1f} evaluations/pixel"
    )
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="render one image")
    p.add_argument("scene", type=Path)
    add_load_args(p)
    add_camera_args(p)
    p.add_argument(
        "--mode",
        help=f"MODE[:N][+fast|+exact][+lod[:PX]], MODE one of {', '.join(m.label for m in Mode)} or "
        f"preset:NAME ({', '.join(PRESETS)}); default: the mode the file says the scene was trained with "
        "(gbviewer info: trained_as), else scalar; gaussian_blending draws its fast kernel, within 1/1024 of +exact",
    )
    p.add_argument(
        "--supersample",
        type=count(8),
        metavar="1..8",
        help="N x N samples per pixel where --mode gives no :N (default 1)",
    )
    add_lod_arg(p, many=False)
    add_stochastic_args(p)
    p.add_argument("--scale", type=Rate(), default=1.0, help="sampling rate: 8, 1, 0.125 or 1/8")
    add_backend_arg(p)
    p.add_argument(
        "--background",
        type=BACKGROUND,
        default=(0.0, 0.0, 0.0),
        metavar=BACKGROUND.metavar,
        help="background colour, each in 0..1",
    )
    p.add_argument(
        "--sh-degree", type=count(3, lo=0), metavar="0..3", help="SH degree drawn (default 3, a preset's own bands)"
    )
    p.add_argument("--out", required=True, help="FILE.png or FILE.npy (float32 RGB)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_render)
