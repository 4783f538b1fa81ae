"""Scale benchmark: a shared capture tiled to ~1 M and ~6.1 M splats (built once into the user cache folder, reused
while its record matches), then load against a raw read, peak RSS, stage times, two-pane time and cancel latency.

    nice python bench/scale.py [--sizes 1m,6m] [--repeat 1] [--json out.json]
    python bench/scale.py --build-only        # just build (or check) the tiled scenes; prints their paths
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from gbviewer.bench.scale import print_scale, run_scale
from gbviewer.bench.scale_scene import TILES, tiled_scene

# The capture it tiles by default: the scenes folder beside this checkout (--source names another).
DEFAULT_SOURCE = Path(__file__).resolve().parents[1].parent / "shared" / "scenes" / "biker.compressed.ply"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1m,6m", help=f"comma-separated of {sorted(TILES)}")
    ap.add_argument("--source", type=Path, default=DEFAULT_SOURCE)
    ap.add_argument("--cache", type=Path, help="folder of the tiled scenes (default: the user cache folder)")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--modes", default="scalar,gaussian_blending")
    ap.add_argument("--rates", default="1,0.125")
    ap.add_argument("--cancel-at", default="50,300,1000", help="ms after the start of a render to set its event")
    ap.add_argument("--build-only", action="store_true")
    ap.add_argument("--verify", action="store_true", help="rehash a cached scene before reusing it")
    ap.add_argument("--json", type=Path, help="write the results here")
    args = ap.parse_args()
    sizes = args.sizes.split(",")
    bad = [s for s in sizes if s not in TILES]
    if bad:
        ap.error(f"--sizes: {bad[0]!r}; expected one of {sorted(TILES)}")
    paths = {s: tiled_scene(TILES[s], args.source, args.cache, args.verify) for s in sizes}
    if args.build_only:
        for s, p in paths.items():
            print(f"{s}: {p}")
        return
    print(f"cpu count {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")
    results = []
    for p in paths.values():
        r = run_scale(
            p,
            args.repeat,
            args.modes.split(","),
            [float(x) for x in args.rates.split(",")],
            [float(x) for x in args.cancel_at.split(",")],
        )
        r["load_average"] = os.getloadavg()[0]
        print_scale(r)
        results.append(r)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
