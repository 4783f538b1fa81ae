"""Bit-identity check for restructurings of a renderer: save every mode's frames (rgb, alpha, debug planes, counts)
and a few pixel traces of some scenes with one build, then compare another build's against them exactly.

    python tools/frame_snapshot.py save before.pkl          # with the build before the change
    python tools/frame_snapshot.py compare before.pkl       # with the build after it: exit 1 on any difference

Scenes: the files given with --scene, else ../shared/scenes' fruit_drops_minimal.ply, plant.splat, st-peter.sog and
v3dg-donut.fused.ply where present; always also a random scene with sort-free view weights (wsr / duplex with trained
weights). Every mode at supersample 1, 2, 3 with the window debug plane, on a 56x40 orbit view; traces of two pixels
at supersample 1 and 2. Frames compare with np.array_equal, counts (visible, pairs, sort_length, evaluations,
cells_visible, cell_misses) and trace JSON with ==.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

import gbviewer as gb

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "scenes"
DEFAULT_SCENES = ("fruit_drops_minimal.ply", "plant.splat", "st-peter.sog", "v3dg-donut.fused.ply")
MODES = (*(m.label for m in gb.Mode), "stopthepop:0")  # every mode; stopthepop also with the exact per-pixel sort
PIXELS = ((28, 20), (10, 33))
BACKGROUND = (0.1, 0.2, 0.3)


def weighted_scene() -> gb.Scene:
    """300 random splats in front of the origin with random view-weight SH (some negative from some directions)."""
    rng = np.random.default_rng(7)
    n = 300
    means = np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 6, n)]
    vw = rng.normal(0.0, 0.4, (n, 16))
    vw[:, 0] += 1.5
    return gb.Scene.from_arrays(
        means,
        rng.uniform(0.02, 0.2, (n, 3)),
        rng.normal(size=(n, 4)),
        rng.uniform(0.1, 0.9, n),
        rng.uniform(-1, 1, (n, 9, 3)),
        view_weight_sh=vw,
        wsr_sigma=5.0,
        weight_background=0.3,
    )


def snapshot(paths: list[Path]) -> dict:
    """(scene, mode, supersample) -> planes and counts; (scene, mode, supersample, x, y) -> trace JSON."""
    scenes = {p.name: gb.load(p) for p in paths}
    scenes["weighted"] = weighted_scene()
    out: dict = {}
    for name, scene in scenes.items():
        cam = gb.orbit_camera(scene, width=56, height=40)
        for mode in MODES:
            for ss in (1, 2, 3):
                f = gb.render(scene, cam, mode, supersample=ss, debug="window", background=BACKGROUND)
                s = f.stats
                out[name, mode, ss] = {
                    "rgb": f.rgb,
                    "alpha": f.alpha,
                    **f.debug,
                    "counts": (s.visible, s.pairs, s.sort_length, s.evaluations, s.cells_visible, s.cell_misses),
                }
            for x, y in PIXELS:
                for ss in (1, 2):
                    out[name, mode, ss, x, y] = gb.trace_pixel(
                        scene, cam, x, y, mode, supersample=ss, background=BACKGROUND
                    ).to_json()
    return out


def same(a: dict | str, b: dict | str) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return a.keys() == b.keys() and all(a[k] == b[k] if k == "counts" else np.array_equal(a[k], b[k]) for k in a)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=("save", "compare"))
    ap.add_argument("file", type=Path, help="the snapshot (a pickle this tool wrote)")
    ap.add_argument("--scene", type=Path, action="append", help="a scene file (repeatable)")
    args = ap.parse_args(argv)
    paths = args.scene or [SHARED / n for n in DEFAULT_SCENES if (SHARED / n).exists()]
    now = snapshot(paths)
    if args.action == "save":
        args.file.write_bytes(pickle.dumps(now))
        print(f"{len(now)} frames and traces saved to {args.file}")
        return 0
    saved = pickle.loads(args.file.read_bytes())
    differ = sorted(map(str, set(saved) ^ set(now))) + [
        str(k) for k in saved if k in now and not same(saved[k], now[k])
    ]
    for k in differ:
        print("differs:", k)
    print(f"{len(saved)} compared, {len(differ)} differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
