"""Load time of a synthetic N-splat scene (default 1M) in every format, against reading its bytes.

    python bench/load_speed.py [--n 1000000] [--repeat 3] [--formats inria-sh3,spz4,...] [--dir DIR]

Files are written with the format encoders (tools/encoders.py) and gbviewer's INRIA writer, then read
with a warm page cache: "raw read" is the best time to read every byte of the file (or the SOG
folder), "load" the best time of gb.load() to a validated Scene.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tools"))

import numpy as np  # noqa: E402
from encoders import encode_compressed_ply, encode_splat, encode_spz, random_params, sog_files, write_sog  # noqa: E402

import gbviewer as gb  # noqa: E402

PALETTE = 4096


def _scene(s: dict) -> gb.Scene:
    return gb.Scene.from_arrays(s["means"], s["scales"], s["quats"], s["opacities"], s["sh"])


def _sog(s: dict, path: Path) -> Path:
    rng = np.random.default_rng(1)
    palette = rng.uniform(-0.5, 0.5, (PALETTE,) + s["sh"][:, 1:].shape[1:])
    labels = rng.integers(0, PALETTE, len(s["means"]))
    return write_sog(sog_files(s, palette, labels), path)


WRITERS = {
    "inria-sh3": (3, lambda s, p: gb.io.write_inria_ply(_scene(s), p.with_suffix(".ply"))),
    "inria-sh0": (0, lambda s, p: gb.io.write_inria_ply(_scene(s), p.with_suffix(".ply"))),
    "compressed-ply-sh3": (3, lambda s, p: _bytes(p.with_suffix(".ply"), encode_compressed_ply(s))),
    "spz4-sh3": (3, lambda s, p: _bytes(p.with_suffix(".spz"), encode_spz(s, 4))),
    "spz3-gzip-sh3": (3, lambda s, p: _bytes(p.with_suffix(".spz"), encode_spz(s, 3))),
    "splat": (0, lambda s, p: _bytes(p.with_suffix(".splat"), encode_splat(s))),
    "sog-sh3": (3, lambda s, p: _sog(s, p.with_suffix(".sog"))),
}


def _bytes(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def raw_read(path: Path) -> int:
    return sum(len(f.read_bytes()) for f in ([path] if path.is_file() else sorted(path.iterdir())))


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", default=",".join(WRITERS))
    ap.add_argument("--dir", type=Path, help="where to write the files (default: a temporary folder)")
    args = ap.parse_args()
    scenes = {deg: random_params(args.n, sh_degree=deg, seed=deg) for deg in (0, 3)}
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.dir or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        print(f"{'format':<20}{'MB':>8}{'raw read ms':>13}{'load ms':>10}{'load/raw':>10}")
        for name in args.formats.split(","):
            degree, write = WRITERS[name]
            path = write(scenes[degree], folder / name)
            size = raw_read(path)
            t_raw = best(lambda p=path: raw_read(p), args.repeat)
            t_load = best(lambda p=path: gb.load(p), args.repeat)
            assert gb.load(path).num_splats == args.n
            print(f"{name:<20}{size / 1e6:>8.1f}{t_raw * 1e3:>13.1f}{t_load * 1e3:>10.1f}{t_load / t_raw:>10.1f}")


if __name__ == "__main__":
    main()
