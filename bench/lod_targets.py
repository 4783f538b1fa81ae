"""Level of detail against its targets (docs/lod.md), per scene: hierarchy build time against load time, its memory
against the splat arrays, cut selection against the frame, LOD render time against the full render, and the merge
rules' PSNR (tau = 1 px) against the full render at the same rate and against the zoom-out reference (the x1 scalar
render box-downsampled), beside plain scalar, gaussian_blending and scalar 3x3.

    nice python bench/lod_targets.py [SCENE ...] [--size 640x480] [--rates 1,1/4,1/8] [--tau 1] [--json out.json]

Default scenes: /work/shared/scenes/*. Times are the best of `--repeat` (after one warm-up): of one camera (the
stage and cut kept, as for a still camera), and of cameras each a little moved (every frame builds them).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gbviewer as gb
from gbviewer import lod
from gbviewer.bench.scale import scene_bytes
from gbviewer.model.camera import orbit_camera, parse_rates
from gbviewer.outputs.metrics import psnr, reference_psnr

RULES = lod.tree.RULES
OTHERS = ("scalar", "gaussian_blending", "scalar:3")


def best(fn, repeat: int) -> tuple[float, object]:
    """The fastest of `repeat` calls after a warm-up, in ms, and its result."""
    out = fn()
    ms = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ms.append((time.perf_counter() - t) * 1e3)
    return min(ms), out


def moving(render, cams: list) -> float:
    """The fastest frame, in ms, of `render(camera)` over cameras that each differ a little (every frame builds its
    stage and cut, as while the camera moves), after a warm-up on the first."""
    render(cams[0])
    ms = []
    for cam in cams[1:]:
        t = time.perf_counter()
        render(cam)
        ms.append((time.perf_counter() - t) * 1e3)
    return min(ms)


def measure(
    path: Path, size: tuple[int, int], rates: list[float], tau: float, repeat: int, rules: tuple[str, ...] = RULES
) -> dict:
    load_ms, scene = best(lambda: gb.load(path), repeat)
    build_ms, tree = best(lambda: lod.build(scene), repeat)
    row = {
        "scene": path.name,
        "splats": scene.num_splats,
        "load_ms": load_ms,
        "build_ms": build_ms,
        "tree_bytes": tree.nbytes,
        "scene_bytes": scene_bytes(scene),
        "rates": [],
    }
    cam = orbit_camera(scene, width=size[0], height=size[1])
    renderer = gb.get_renderer(scene, "cpu")
    ref_x1 = renderer.render(cam, gb.RenderSettings()).rgb
    for rate in rates:
        view = cam.at_sampling_rate(rate)
        full_ms, full = best(lambda v=view: renderer.render(v, gb.RenderSettings()), repeat)
        lod_ms, frame = best(lambda v=view: renderer.render(v, gb.RenderSettings(lod=tau)), repeat)
        cut_ms, c = best(lambda v=view: lod.cut(tree, v, tau), repeat)
        cams = [
            orbit_camera(scene, 30.0 + 0.01 * k, width=size[0], height=size[1]).at_sampling_rate(rate)
            for k in range(repeat + 1)
        ]
        r = {
            "rate": rate,
            "full_ms": full_ms,
            "lod_ms": lod_ms,
            "cut_ms": cut_ms,
            "drawn": c.num_drawn,
            "psnr": {},
            "moving_full_ms": moving(lambda v: renderer.render(v, gb.RenderSettings()), cams),
            "moving_lod_ms": moving(lambda v: renderer.render(v, gb.RenderSettings(lod=tau)), cams),
        }
        for rule in rules:
            img = gb.get_renderer(lod.cut_scene(scene, view, tau, rule=rule), "cpu").render(view, gb.RenderSettings())
            r["psnr"][f"lod-{rule}"] = (psnr(img.rgb, full.rgb), reference_psnr(ref_x1, img.rgb, rate))
        for spec in OTHERS:
            img = renderer.render(view, gb.RenderSettings.parse(spec)).rgb
            r["psnr"][spec] = (psnr(img, full.rgb), reference_psnr(ref_x1, img, rate))
        row["rates"].append(r)
    return row


def show(row: dict) -> None:
    print(
        f"\n{row['scene']}: {row['splats']:,} splats | load {row['load_ms']:.0f} ms, build {row['build_ms']:.0f} ms "
        f"({row['build_ms'] / row['load_ms']:.0%}) | tree {row['tree_bytes'] / 2**20:.1f} MiB = "
        f"{row['tree_bytes'] / row['scene_bytes']:.0%} of the splat arrays"
    )
    for r in row["rates"]:
        # the still frame keeps its cut: the moving frame is the one that computes it
        print(
            f"  x{r['rate']:g}: full {r['full_ms']:.0f} ms, lod {r['lod_ms']:.0f} ms ({r['full_ms'] / r['lod_ms']:.1f}x"
            f" faster), cut {r['cut_ms']:.1f} ms ({r['cut_ms'] / r['moving_lod_ms']:.0%} of the moving lod frame), "
            f"{r['drawn']:,} drawn; moving camera: full {r['moving_full_ms']:.0f} ms, lod {r['moving_lod_ms']:.0f} ms "
            f"({r['moving_full_ms'] / r['moving_lod_ms']:.1f}x)"
        )
        for name, (vs_full, vs_ref) in r["psnr"].items():
            ref = "" if vs_ref is None else f", {vs_ref:.2f} dB vs reference"
            print(f"    {name:<18} {vs_full:6.2f} dB vs full{ref}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--rates", default="1,1/4,1/8")
    ap.add_argument("--tau", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--rules", default=",".join(RULES), help="merge rules whose cuts' PSNR is measured")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rules = tuple(args.rules.split(",")) if args.rules else ()
    if any(r not in RULES for r in rules):
        ap.error(f"--rules {args.rules!r}: expected a comma-separated subset of {','.join(RULES)}")
    scenes = args.scenes or sorted(p for p in Path("/work/shared/scenes").iterdir() if p.suffix != ".md")
    size = tuple(int(v) for v in args.size.split("x"))
    rows = []
    for path in scenes:
        rows.append(measure(path, size, parse_rates(args.rates), args.tau, args.repeat, rules))
        show(rows[-1])
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
