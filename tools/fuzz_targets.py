"""The fuzz targets beyond single scene files, for tools/fuzz_loaders.py and its regression replays: datasets and
command lines, each read from the one input file the fuzzer writes.

- colmap_bin: u32 length L, then L bytes of cameras.bin, then images.bin (a model of 8x6 photos a.png, b.png, ...)
- colmap_txt: cameras.txt, a NUL byte, images.txt
- colmap_doc: the JSON the pycolmap child prints (`colmap.read_colmap`'s result), for `load_colmap`'s checks
- blender: transforms_test.json beside test/a.png ... (8x6 RGBA)
- cameras_dataset: a 3DGS cameras.json beside images/a.png ...
- photo: the bytes of one photo (read_photo)
- eval_args, trace_args: a command line, one argument per line, after `gbviewer eval` (its work replaced by a stub:
  the options and the checks before the work are the target) or `gbviewer trace tiny.ply` (a five-splat scene)
- lod_entry: a level-of-detail cache entry (.npz) of the fixed scene `_lod_scene` (its seed: the entry gbviewer
  writes), found in the cache by a render at tau 2 px: a bad entry is rebuilt (one warning), a good one drawn in
  place and gathered
"""

from __future__ import annotations

import atexit
import contextlib
import io
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np

PHOTOS = ("a", "b", "c", "d")
_SCRATCH: Path | None = None


class ReachedWork(Exception):
    """Raised by the stub of eval's work: every option was accepted."""


def _photos(folder: Path, suffix: str = ".png", mode: str = "RGB") -> None:
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    for name in PHOTOS:
        Image.new(mode, (8, 6), (40, 90, 200, 255)[: len(mode)]).save(folder / f"{name}{suffix}")


def _fresh(path: Path) -> Path:
    """An empty folder for the dataset or command made of `path`, in this process's scratch folder (removed at
    exit), never beside the input: seeds and crashes are replayed where they are kept."""
    global _SCRATCH
    if _SCRATCH is None:
        _SCRATCH = Path(tempfile.mkdtemp(prefix="gbv-fuzz-targets-"))
        atexit.register(shutil.rmtree, _SCRATCH, ignore_errors=True)
    root = _SCRATCH / path.name
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir()
    return root


def _views(dataset) -> list[np.ndarray]:
    from fuzz_loaders import _camera_arrays

    return _camera_arrays([v.camera for v in dataset.views])


def _load(root: Path) -> list[np.ndarray]:
    from gbviewer.io.datasets import load_dataset

    return _views(load_dataset(root))


def colmap_bin(path: Path) -> list[np.ndarray]:
    data = path.read_bytes()
    n = struct.unpack("<I", data[:4])[0] if len(data) >= 4 else 0
    root = _fresh(path)
    (root / "sparse" / "0").mkdir(parents=True)
    (root / "sparse" / "0" / "cameras.bin").write_bytes(data[4 : 4 + n])
    (root / "sparse" / "0" / "images.bin").write_bytes(data[4 + n :])
    _photos(root / "images")
    return _load(root)


def colmap_txt(path: Path) -> list[np.ndarray]:
    cameras, _, images = path.read_bytes().partition(b"\0")
    root = _fresh(path)
    (root / "sparse" / "0").mkdir(parents=True)
    (root / "sparse" / "0" / "cameras.txt").write_bytes(cameras)
    (root / "sparse" / "0" / "images.txt").write_bytes(images)
    _photos(root / "images")
    return _load(root)


def colmap_doc(path: Path) -> list[np.ndarray]:
    """The checks `load_colmap` applies to what the pycolmap child prints (the child's JSON as the input; fast: no
    child process)."""
    from gbviewer.io.datasets import colmap

    root = _fresh(path)
    (root / "sparse" / "0").mkdir(parents=True)
    (root / "sparse" / "0" / "cameras.txt").write_text("")
    _photos(root / "images")
    real = colmap.read_colmap
    colmap.read_colmap = lambda model: _child_doc(path, real)
    try:
        return _load(root)
    finally:
        colmap.read_colmap = real


def _child_doc(path: Path, read_colmap) -> dict:
    """The input parsed as read_colmap parses the child's output (NaN and Infinity kept)."""
    import json

    from gbviewer.core.errors import DatasetError

    try:
        doc = json.loads(path.read_bytes())
        if not _shaped(doc):
            raise ValueError("not shaped as the child prints")
    except (ValueError, RecursionError, TypeError, KeyError, AttributeError) as exc:
        raise DatasetError(f"not the child's output ({str(exc)[:60]})") from None
    return doc


def _shaped(doc) -> bool:
    """Whether `doc` has the keys and types the child always prints (pycolmap's values in them are the target):
    cameras {id: model, width, height, params, names with cx, cy and f or fx, fy}, images [name, camera, q, R, t]."""

    def numbers(v, n):
        return isinstance(v, list) and len(v) == n and all(type(x) in (int, float) for x in v)

    cams_ok = isinstance(doc["cameras"], dict) and all(
        isinstance(c["model"], str)
        and type(c["width"]) is int
        and type(c["height"]) is int
        and numbers(c["params"], len(c["names"]))
        and all(isinstance(n, str) for n in c["names"])
        and {"cx", "cy"} <= set(c["names"])
        and ("f" in c["names"] or {"fx", "fy"} <= set(c["names"]))
        for c in doc["cameras"].values()
    )
    return (
        cams_ok
        and isinstance(doc["images"], list)
        and all(
            isinstance(im["name"], str)
            and isinstance(im["camera"], str)
            and numbers(im["q"], 4)
            and numbers(im["t"], 3)
            and isinstance(im["R"], list)
            and len(im["R"]) == 3
            and all(numbers(r, 3) for r in im["R"])
            for im in doc["images"]
        )
    )


def blender(path: Path) -> list[np.ndarray]:
    root = _fresh(path)
    shutil.copyfile(path, root / "transforms_test.json")
    _photos(root / "test", mode="RGBA")
    return _load(root)


def cameras_dataset(path: Path) -> list[np.ndarray]:
    root = _fresh(path)
    shutil.copyfile(path, root / "cameras.json")
    _photos(root / "images")
    return _load(root)


def photo(path: Path) -> list[np.ndarray]:
    from gbviewer.io.datasets import read_photo

    return [read_photo(path)]


def _run_cli(argv: list[str], cwd: Path) -> list[np.ndarray]:
    """`gbviewer ARGV` in `cwd`: exit status 0, or 2 with one line on stderr (a GBViewerError for check_load)."""
    import gbviewer as gb
    from gbviewer import cli

    err = io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = cli.main(argv)
        except ReachedWork:
            return []
    lines = err.getvalue().splitlines()
    if status == 2 and len([ln for ln in lines if ln.startswith("gbviewer")]) == 1:
        raise gb.GBViewerError(lines[-1])
    if status != 0:
        raise AssertionError(f"exit status {status} with stderr {err.getvalue()[-300:]!r}")
    return []


def _argv(path: Path) -> list[str]:
    return path.read_bytes().decode("utf-8", "replace").replace("\0", "").splitlines()


def eval_args(path: Path) -> list[np.ndarray]:
    import gbviewer.eval

    def work(*args, **kwargs):
        raise ReachedWork

    real, gbviewer.eval.run_eval = gbviewer.eval.run_eval, work
    try:
        return _run_cli(["eval", *_argv(path)], _fresh(path))
    finally:
        gbviewer.eval.run_eval = real


def trace_args(path: Path) -> list[np.ndarray]:
    import gbviewer as gb
    from gbviewer.io import write_inria_ply

    root = _fresh(path)
    rng = np.random.default_rng(0)
    means = np.column_stack([rng.uniform(-1, 1, (5, 2)), rng.uniform(2, 4, 5)])
    write_inria_ply(
        gb.Scene.from_arrays(
            means, np.full((5, 3), 0.2), np.tile([1.0, 0, 0, 0], (5, 1)), np.full(5, 0.8), np.zeros((5, 1, 3))
        ),
        root / "tiny.ply",
    )
    return _run_cli(["trace", "tiny.ply", *_argv(path)], root)


LOD_SPLATS = 70  # the entry's scene: three levels above its leaves, a partial node on each


def _lod_scene(root: Path):
    """The scene of the lod_entry target, written to `root` and loaded (a fixed file: its content is the cache's
    key), and its camera."""
    import gbviewer as gb
    from gbviewer.io import write_inria_ply

    rng = np.random.default_rng(4)
    n = LOD_SPLATS
    means = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 4, n)])
    scene = gb.Scene.from_arrays(
        means,
        rng.uniform(0.02, 0.2, (n, 3)),
        rng.normal(size=(n, 4)),
        rng.uniform(0.1, 1.0, n),
        rng.normal(0, 0.5, (n, 4, 3)),
    )
    scene = gb.load(write_inria_ply(scene, root / "lod.ply"))
    return scene, gb.Camera(24, 16, 20.0, 20.0, 12.0, 8.0, np.eye(3), np.zeros(3))


def _fixed_crcs(data: bytes) -> bytes:
    """`data` with the CRC-32 of each stored zip member recomputed in its central and local headers (as far as they
    parse): a mutation of the arrays' bytes then reaches the entry's checks instead of failing the zip's CRC."""
    import struct
    import zlib

    out = bytearray(data)
    eocd = out.rfind(b"PK\x05\x06")
    if eocd < 0 or eocd + 22 > len(out):
        return data
    count, _, at = struct.unpack_from("<HII", out, eocd + 10)
    for _ in range(count):
        if at + 46 > len(out) or out[at : at + 4] != b"PK\x01\x02":
            break
        method, size, name_len, extra_len, comment_len, local = (
            struct.unpack_from("<H", out, at + 10)[0],
            *struct.unpack_from("<I", out, at + 20),
            *struct.unpack_from("<HHH", out, at + 28),
            *struct.unpack_from("<I", out, at + 42),
        )
        if method == 0 and local + 30 <= len(out) and out[local : local + 4] == b"PK\x03\x04":
            begin = local + 30 + sum(struct.unpack_from("<HH", out, local + 26))
            crc = zlib.crc32(out[begin : begin + size])
            struct.pack_into("<I", out, at + 16, crc)
            struct.pack_into("<I", out, local + 14, crc)
        at += 46 + name_len + extra_len + comment_len
    return bytes(out)


def lod_entry(path: Path) -> list[np.ndarray]:
    import os
    import warnings

    import gbviewer as gb
    from gbviewer import lod
    from gbviewer.lod.cache import cache_key, default_folder

    root = _fresh(path)
    scene, camera = _lod_scene(root)
    before = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(root / "cache")  # the user cache folder (platformdirs) of this input
    try:
        folder = default_folder()
        folder.mkdir(parents=True)
        (folder / f"{cache_key(scene, 'depth')}.npz").write_bytes(_fixed_crcs(path.read_bytes()))
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", ".*damaged level-of-detail cache entry", UserWarning)
            frame = gb.render(scene, camera, "scalar", lod=2.0, threads=1)
    finally:
        if before is None:
            os.environ.pop("XDG_CACHE_HOME")
        else:
            os.environ["XDG_CACHE_HOME"] = before
    cut = lod.cut_scene(scene, camera, 2.0, threads=1)  # the same tree, gathered
    return [frame.rgb, frame.alpha, *cut.arrays.values()]


READERS = {
    f.__name__: f
    for f in (colmap_bin, colmap_txt, colmap_doc, blender, cameras_dataset, photo, eval_args, trace_args, lod_entry)
}
