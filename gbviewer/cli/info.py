"""`gbviewer info` and `gbviewer convert`: describe a scene file and how the native modules were built (alone
without a scene), write a scene in any format gbviewer reads."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..core.files import check_writable
from ..io import WRITE_FORMATS, dropped, format_for, load, save
from ..io.trained_as import describe
from ..render import build_info, compiler_line, simd_line
from .options import add_load_args, load_options

GLTF_KEYS = ("primitives", "compression", "kernel", "projection", "sortingMethod", "colorSpace", "note")


def cmd_info(args: argparse.Namespace) -> int:
    build = build_info()
    if args.scene is None:
        print(json.dumps(build, indent=2) if args.json else f"{simd_line(build)}\n{compiler_line(build)}".rstrip())
        return 0
    scene = load(args.scene, **load_options(args))
    lo, hi = scene.bounds
    rlo, rhi = scene.robust_bounds()
    info = {
        "file": str(args.scene),
        "format": scene.meta.get("format"),
        "version": scene.meta.get("version"),
        "splats": scene.num_splats,
        "sh_degree": scene.sh_degree,
        "filter_3D": scene.filter_3d is not None,
        "trained_as": describe(scene.meta),
        "bounds": [lo.tolist(), hi.tolist()],
        "robust_bounds_2_98": [rlo.tolist(), rhi.tolist()],
        **{key: scene.meta[key] for key in GLTF_KEYS if key in scene.meta},
        "properties": scene.meta.get("properties", []),
        "build": build,
    }
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        for key, val in info.items():
            if key == "properties":
                val = ", ".join(val) if len(val) <= 20 else ", ".join(val[:18]) + f", ... ({len(val)} in all)"
            elif key == "build":
                val = simd_line(val)
            print(f"{key:>20}: {val}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    out = Path(args.out)
    fmt = format_for(out, args.format)
    check_writable(out, args.force, inputs=[args.scene], option="--out")
    scene = load(args.scene, **load_options(args))
    save(scene, out, force=args.force, fmt=fmt)
    print(
        f"{out}: {fmt}, {scene.num_splats} splats, SH degree {scene.sh_degree}, from {scene.meta.get('format')} "
        f"(version {scene.meta.get('version')})"
    )
    if lost := dropped(scene, fmt):
        print(f"{out}: {lost}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info", help="describe a scene file and this build (SIMD paths, OpenMP, compiler; alone without a scene)"
    )
    p.add_argument("scene", type=Path, nargs="?")
    p.add_argument("--json", action="store_true")
    add_load_args(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser(
        "convert",
        help="write a scene in another format (by OUT's name: .ply INRIA, .compressed.ply, "
        ".glb, .spz.glb, .spz, .splat, .sog)",
    )
    p.add_argument("scene", type=Path)
    p.add_argument(
        "out", type=Path, help="OUT.ply, OUT.compressed.ply, OUT.glb, OUT.spz.glb, OUT.spz, OUT.splat or OUT.sog"
    )
    p.add_argument(
        "--format",
        choices=WRITE_FORMATS,
        help="the output format, whatever OUT's name (glb-spz: a .glb "
        "holding an SPZ stream, KHR_gaussian_splatting_compression_spz_2)",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    add_load_args(p)
    p.set_defaults(func=cmd_convert)
