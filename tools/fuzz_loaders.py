"""Coverage-guided fuzzing of the scene loaders with atheris (libFuzzer).

    python tools/fuzz_loaders.py FORMAT [--seconds N] [--corpus DIR] [-- libFuzzer options]

FORMAT is one of the seed folders in tests/io/fuzz/seeds (inria, compressed, spz, splat, sog, gltf, ..., the JSON
readers cameras, keyframes and nerfstudio (camera_path.json), and the datasets and command lines of
tools/fuzz_targets.py): its small seed files start the corpus, new inputs go to `--corpus` (default .fuzz/FORMAT, kept
between runs). An input fails when loading it raises anything but a one-line GBViewerError, emits a numpy
RuntimeWarning, or returns a scene with non-finite values; libFuzzer also flags inputs that take over 10 s (60 s for the
targets of a child process or the CLI) or 2 GiB. Failing inputs are written to tests/io/fuzz/crashes/ where
tests/io/test_fuzz_regressions.py replays them with `check_load` forever after."""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import warnings
from pathlib import Path

import fuzz_targets
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SEEDS = REPO / "tests" / "io" / "fuzz" / "seeds"
CRASHES = REPO / "tests" / "io" / "fuzz" / "crashes"


def _scene_arrays(path: Path) -> list[np.ndarray]:
    import gbviewer as gb

    scene = gb.load(path)
    return [getattr(scene, name) for name in ("means", "scales", "quats", "opacities", "sh")]


def _camera_arrays(cams: list) -> list[np.ndarray]:
    return [np.array([c.R.ravel().tolist() + c.t.tolist() + [c.fx, c.fy, c.cx, c.cy] for c in cams], np.float32)]


def _cameras(path: Path) -> list[np.ndarray]:
    import gbviewer as gb

    return _camera_arrays(gb.load_cameras_json(path))


def _keyframes(path: Path) -> list[np.ndarray]:
    import gbviewer as gb
    from gbviewer.model.keyframes import load_keyframes

    scene = gb.Scene.from_arrays(
        np.eye(3), np.full((3, 3), 0.1), np.tile([1.0, 0, 0, 0], (3, 1)), np.ones(3), np.zeros((3, 1, 3))
    )
    keys = load_keyframes(path, gb.orbit_camera(scene, width=64, height=48), scene)
    return _camera_arrays([k.camera for k in keys]) + [np.array([k.rate for k in keys], np.float32)]


def _nerfstudio(path: Path) -> list[np.ndarray]:
    from gbviewer.model.nerfstudio_paths import load_nerfstudio_path

    p = load_nerfstudio_path(path)
    return _camera_arrays([k.camera for k in p.keys] + list(p.frames)) + [np.array([p.fps, p.seconds], np.float32)]


# the others: scene formats
READERS = {"cameras": _cameras, "keyframes": _keyframes, "nerfstudio": _nerfstudio, **fuzz_targets.READERS}
SLOW = set(fuzz_targets.READERS) - {
    "photo",
    "lod_entry",
}  # a child process per COLMAP input (30 s deadline), or the CLI


def check_load(path: Path, kind: str = "scene") -> str:
    """Read `path` as the CLI would (a scene, or `kind` 'cameras' / 'keyframes'); return 'ok' or 'error', raise
    AssertionError for anything a user must not see: a traceback, a numpy warning, a message of several lines,
    non-finite or float32-overflowing values."""
    import gbviewer as gb

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy over/invalid warnings reaching the user are bugs
        try:
            arrays = READERS.get(kind, _scene_arrays)(path)
        except gb.GBViewerError as exc:
            if "\n" in str(exc) or not str(exc):
                raise AssertionError(f"error message is not one line: {exc!r}") from None
            return "error"
    for a in arrays:
        if not np.isfinite(a).all():
            raise AssertionError("read non-finite values")
    return "ok"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("format", choices=sorted(p.name for p in SEEDS.iterdir()))
    ap.add_argument("--seconds", type=int, default=600, help="fuzzing time (default 600)")
    ap.add_argument("--corpus", type=Path, help="corpus folder kept between runs (default .fuzz/FORMAT)")
    args, extra = ap.parse_known_args()
    sys.path.insert(0, str(REPO))  # fuzz the working tree (with its compiled module copied in) rather than an install
    corpus = args.corpus or REPO / ".fuzz" / args.format
    corpus.mkdir(parents=True, exist_ok=True)
    CRASHES.mkdir(parents=True, exist_ok=True)

    import atheris

    with atheris.instrument_imports(include=["gbviewer", "PIL"]):  # PIL: which of its errors reach us
        import PIL.JpegImagePlugin
        import PIL.PngImagePlugin  # noqa: F401

        import gbviewer.cli
        import gbviewer.io
        import gbviewer.io.datasets
        import gbviewer.model.keyframes  # noqa: F401
    scratch = Path(tempfile.mkdtemp(prefix="gbv-fuzz-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    target = scratch / "input"

    def one_input(data: bytes) -> None:
        target.write_bytes(data)
        try:
            check_load(target, args.format)
        except Exception:  # saved here too: atheris does not always write the artifact of a Python exception
            (CRASHES / f"{args.format}-crash-{hashlib.sha1(data).hexdigest()}").write_bytes(data)
            raise

    flags = [
        sys.argv[0],
        str(corpus),
        str(SEEDS / args.format),
        f"-max_total_time={args.seconds}",
        f"-timeout={60 if args.format in SLOW else 10}",
        "-rss_limit_mb=2048",
        f"-artifact_prefix={CRASHES}/{args.format}-",
        "-print_final_stats=1",
        *extra,
    ]
    atheris.Setup(flags, one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
