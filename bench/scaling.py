"""How render time and memory grow with splat count and with pixel count (CPU backend, synthetic scenes).

    python bench/scaling.py [--max-splats 10000000] [--simd avx2] [--json OUT.json]

Each point runs in its own process so that its peak resident memory is its own; time is the median of
`--repeat` renders after a warm-up. `--simd` sets GBVIEWER_SIMD for those processes (default: the variable as it
is, else the best path); every point records the path that ran."""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SPLATS = [10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000, 10_000_000]
SIZES = [(160, 120), (320, 240), (640, 480), (1280, 960)]


def measure_point(n: int, width: int, height: int, mode: str, repeat: int) -> dict:
    """One measurement in this process (called in a child)."""
    sys.path.insert(0, str(HERE))
    import synthetic

    import gbviewer as gb

    scene = synthetic.make_scene(n)
    rss_scene = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    cam = gb.orbit_camera(scene, 30, 25, width=width, height=height, up="+z")
    renderer = gb.get_renderer(scene, "cpu")
    settings = gb.RenderSettings(gb.Mode.parse(mode))
    renderer.render(cam, settings)
    frames = [renderer.render(cam, settings).stats for _ in range(repeat)]
    med = {
        k: statistics.median(getattr(f, k) for f in frames)
        for k in ("total_ms", "preprocess_ms", "sort_ms", "blend_ms")
    }
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "splats": n,
        "width": width,
        "height": height,
        "mode": mode,
        **med,
        "sort_length": frames[-1].sort_length,
        "evals_per_pixel": frames[-1].evals_per_pixel,
        "simd": frames[-1].simd,
        "scene_rss_mib": rss_scene / 1024,
        "peak_rss_mib": peak / 1024,
    }


def run_point(n: int, width: int, height: int, mode: str, repeat: int, simd: str | None = None) -> dict:
    env = dict(os.environ, **({"GBVIEWER_SIMD": simd} if simd else {}))
    out = subprocess.run(
        [sys.executable, __file__, "--point", str(n), str(width), str(height), mode, str(repeat)],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(max_splats: int, repeat: int, modes: list[str], progress=print, simd: str | None = None) -> dict:
    """Splat series at 640x480 and pixel series at 300k splats, for each mode (on SIMD path `simd`: None, the one
    GBVIEWER_SIMD or the CPU chooses)."""
    rows = {"splats": [], "pixels": []}
    for mode in modes:
        for n in [s for s in SPLATS if s <= max_splats]:
            rows["splats"].append(run_point(n, 640, 480, mode, repeat, simd))
            progress(f"{mode} {n} splats ({rows['splats'][-1]['simd']}): {rows['splats'][-1]['total_ms']:.0f} ms")
        for w, h in SIZES:
            rows["pixels"].append(run_point(300_000, w, h, mode, repeat, simd))
            progress(f"{mode} {w}x{h} ({rows['pixels'][-1]['simd']}): {rows['pixels'][-1]['total_ms']:.0f} ms")
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--point", nargs=5, help=argparse.SUPPRESS)
    parser.add_argument("--max-splats", type=float, default=10_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--modes", default="scalar,gaussian_blending")
    parser.add_argument("--simd", help="GBVIEWER_SIMD for the measuring processes: scalar, avx2 or avx512")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if args.point:
        n, w, h, mode, repeat = args.point
        print(json.dumps(measure_point(int(n), int(w), int(h), mode, int(repeat))))
        return 0
    rows = run(int(args.max_splats), args.repeat, args.modes.split(","), simd=args.simd)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
