"""CPU time of gaussian_blending+fast against scalar, per scene and SIMD path, the two modes taking turns.

    python bench/fast_gb_ratio.py SCENE... [--paths avx512,avx2] [--repeat 5] [--size 640x480]

Process CPU time (both blend threads, user + system) of each render, not wall time: on a machine shared with other
jobs a frame's wall time depends on who else runs, its CPU time much less. Prints one line per scene and path: the
median ms of each mode, their ratio (the target is <= 1.5), and the splat-pixel evaluations of each mode.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import gbviewer as gb
from gbviewer import _native
from gbviewer.render import RenderSettings, create_renderer

MODES = ("scalar", "gaussian_blending+fast")


def cpu_ms(renderer, cam: gb.Camera, settings: RenderSettings) -> tuple[float, int]:
    start = time.process_time()
    frame = renderer.render(cam, settings)
    return (time.process_time() - start) * 1000.0, frame.stats.evaluations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--paths", default="avx512,avx2", help="SIMD paths (those this CPU lacks are skipped)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--size", default="640x480")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    settings = {m: RenderSettings.parse(m) for m in MODES}
    for name in args.scenes:
        scene = gb.load(name)
        cam = gb.orbit_camera(scene, 30, 20, width=width, height=height)
        for path in args.paths.split(","):
            if path not in _native.simd_paths():
                continue
            _native.testing.set_simd(path)
            renderer = create_renderer("cpu")
            renderer.upload(scene)
            for m in MODES:  # warm: the per-camera stage and the buffers
                renderer.render(cam, settings[m])
            ms: dict[str, list[float]] = {m: [] for m in MODES}
            evals: dict[str, int] = {}
            for _ in range(args.repeat):
                for m in MODES:
                    t, evals[m] = cpu_ms(renderer, cam, settings[m])
                    ms[m].append(t)
            med = {m: float(np.median(ms[m])) for m in MODES}
            print(
                f"{name} {path}: scalar {med['scalar']:.0f} ms, fast {med[MODES[1]]:.0f} ms, "
                f"ratio {med[MODES[1]] / med['scalar']:.2f}; evaluations {evals['scalar'] / 1e6:.1f}M, "
                f"{evals[MODES[1]] / 1e6:.1f}M",
                flush=True,
            )


if __name__ == "__main__":
    main()
