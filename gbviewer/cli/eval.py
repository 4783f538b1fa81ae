"""`gbviewer eval`: PSNR and SSIM against the training photos."""

from __future__ import annotations

import argparse

from ..core.extras import require
from ..core.files import check_writable
from ..core.outputs import refuse_collisions
from .eval_args import add_eval_args, scene_pairs
from .options import add_lod_arg, add_stochastic_args, progress_bar, settings_of


def cmd_eval(args: argparse.Namespace) -> int:
    """PSNR and SSIM of every mode at every rate against the training photos (the paper's tables)."""
    from .. import eval as evaluation

    require("eval", "skimage", "gbviewer eval (SSIM)", load=False)
    if args.plots:
        require("eval", "matplotlib", "--plots", load=False)
    pairs = scene_pairs(args.scenes, args.data)
    outputs = [args.json] * bool(args.json) + (evaluation.plot_paths(args.plots, pairs) if args.plots else [])
    refuse_collisions(outputs)
    for path in outputs:
        check_writable(path, args.force, inputs=[p for pair in pairs for p in pair])
    result = evaluation.run_eval(
        pairs,
        settings_of(args),
        args.rates,
        split=args.split,
        background=args.background,
        images=args.images,
        backend=args.backend,
        workers=args.workers,
        ray=args.ray,
        threads=args.threads,
        cache=args.cache or evaluation.default_cache(),
        progress=progress_bar,
    )
    evaluation.print_tables(result)
    if args.json:
        print(f"wrote {evaluation.write_json(args.json, result, args.force)}")
    if args.plots:
        for path in evaluation.write_plots(args.plots, result, args.force):
            print(f"wrote {path}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval",
        help="PSNR and SSIM of every mode and sampling rate against a scene's training "
        "photos (COLMAP, Blender or cameras.json datasets), the paper's tables",
    )
    add_eval_args(p)
    add_lod_arg(p)
    add_stochastic_args(p)
    p.set_defaults(func=cmd_eval)
