"""Bad, truncated and fuzzed files of every format give a one-line SceneFormatError, never a crash."""

from __future__ import annotations

import io
import json
import struct
import zipfile

import numpy as np
import pytest
from encoders import encode_compressed_ply, encode_splat, encode_spz, random_params, sog_files

import gbviewer as gb
from gbviewer.core.errors import SceneFormatError


def _inria(s: dict, tmp_path) -> bytes:
    scene = gb.Scene.from_arrays(s["means"], s["scales"], s["quats"], s["opacities"], s["sh"])
    return gb.io.write_inria_ply(scene, tmp_path / "inria.ply").read_bytes()


def _sog_zip(s: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data in sog_files(s).items():
            zf.writestr(name, data)
    return buf.getvalue()


@pytest.fixture(scope="module")
def samples(tmp_path_factory) -> dict[str, bytes]:
    s = random_params(300, sh_degree=1, seed=3)
    s0 = random_params(300, seed=4)
    return {
        "inria": _inria(s, tmp_path_factory.mktemp("inria")),
        "compressed": encode_compressed_ply(s),
        "spz2": encode_spz(s, 2),
        "spz3raw": encode_spz(s, 3, gzipped=False),
        "spz4": encode_spz(s, 4),
        "splat": encode_splat(s0),
        "sog": _sog_zip(s0),
    }


def outcome(path) -> str:
    """'ok' or 'error'; any exception other than a one-line SceneFormatError fails the test."""
    try:
        gb.load(path)
    except SceneFormatError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return "error"
    return "ok"


FORMATS = ["inria", "compressed", "spz2", "spz3raw", "spz4", "splat", "sog"]


@pytest.mark.parametrize("fmt", FORMATS)
def test_valid_sample_loads(samples, tmp_path, fmt):
    (tmp_path / "f").write_bytes(samples[fmt])
    assert outcome(tmp_path / "f") == "ok"


@pytest.mark.parametrize("fmt", FORMATS)
def test_truncated(samples, tmp_path, fmt):
    data = samples[fmt]
    cuts = sorted({0, 1, 3, 8, 15, 16, 31, 33, 64, 100, len(data) // 3, len(data) // 2, len(data) - 7, len(data) - 1})
    path = tmp_path / "t"
    for cut in cuts:
        path.write_bytes(data[:cut])
        whole_records = fmt == "splat" and cut % 32 == 0 and cut > 0
        assert outcome(path) == ("ok" if whole_records else "error"), f"cut at {cut} of {len(data)}"


@pytest.mark.parametrize("fmt", FORMATS)
def test_fuzzed(samples, tmp_path, fmt):
    rng = np.random.default_rng(hash(fmt) % 2**32)
    data = np.frombuffer(samples[fmt], np.uint8)
    path = tmp_path / "z"
    for i in range(40):
        fuzzed = data.copy()
        # first half of the runs hit the first 256 bytes (headers, TOC, zip entries), the rest anywhere
        span = min(len(data), 256) if i < 20 else len(data)
        where = rng.integers(0, span, rng.integers(1, 9))
        fuzzed[where] = rng.integers(0, 256, len(where))
        path.write_bytes(fuzzed.tobytes())
        outcome(path)


def _message(path) -> str:
    with pytest.raises(SceneFormatError) as info:
        gb.load(path)
    return str(info.value)


def test_corrupt_zstd_stream_is_named(samples, tmp_path):
    data = bytearray(samples["spz4"])
    toc = struct.unpack_from("<I", data, 16)[0]
    first = struct.unpack_from("<Q", data, toc)[0]  # compressed size of stream 0 (positions)
    start = toc + data[15] * 16 + first + 1  # inside stream 1 (alphas)
    data[start : start + 8] = b"\xff" * 8
    (tmp_path / "bad.spz").write_bytes(bytes(data))
    assert "stream 'alphas'" in _message(tmp_path / "bad.spz")


def test_unknown_spz_versions(samples, tmp_path):
    v9 = bytearray(samples["spz4"])
    v9[4] = 9
    (tmp_path / "v9.spz").write_bytes(bytes(v9))
    assert "version 9" in _message(tmp_path / "v9.spz")
    raw = bytearray(samples["spz3raw"])
    raw[4] = 0
    (tmp_path / "v0.spz").write_bytes(bytes(raw))
    assert "version 0" in _message(tmp_path / "v0.spz")


def test_count_larger_than_data(samples, tmp_path):
    for fmt, expect in [("spz4", "TOC says"), ("spz3raw", "truncated")]:
        data = bytearray(samples[fmt])
        struct.pack_into("<I", data, 8, 10_000)
        (tmp_path / fmt).write_bytes(bytes(data))
        assert expect in _message(tmp_path / fmt)
    ply = samples["inria"].replace(b"element vertex 300", b"element vertex 900")
    (tmp_path / "big.ply").write_bytes(ply)
    assert "vertex" in _message(tmp_path / "big.ply")
    cply = samples["compressed"].replace(b"element vertex 300", b"element vertex 301")
    (tmp_path / "bigc.ply").write_bytes(cply)
    _message(tmp_path / "bigc.ply")


def test_sog_missing_image_and_bad_meta(tmp_path):
    files = sog_files(random_params(100, seed=9))
    del files["quats.webp"]
    with zipfile.ZipFile(tmp_path / "m.sog", "w") as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    assert "quats.webp" in _message(tmp_path / "m.sog")
    meta = json.loads(files["meta.json"])
    for change, expect in [({"version": 3}, "version"), ({"count": 10**6}, "holding"), ({"count": "x"}, "count")]:
        folder = tmp_path / f"d{expect}"
        folder.mkdir()
        for name, data in files.items():
            (folder / name).write_bytes(data)
        (folder / "meta.json").write_text(json.dumps({**meta, **change}))
        assert expect in _message(folder)


def test_unrecognised_and_missing(tmp_path):
    (tmp_path / "junk").write_bytes(b"hello world, not a scene at all")
    assert "unrecognised scene format" in _message(tmp_path / "junk")
    assert "no such file" in _message(tmp_path / "missing.spz")
    (tmp_path / "empty_dir").mkdir()
    assert "meta.json" in _message(tmp_path / "empty_dir")


@pytest.mark.parametrize("name", ["meta.json", "means_l.webp"])
def test_a_sog_folder_file_that_is_a_fifo_is_one_line(tmp_path, name):
    """A SOG folder's meta.json or image as a FIFO blocked the load in open() forever (gbviewer info hung)."""
    import os
    import subprocess
    import sys

    files = sog_files(random_params(50, seed=10))
    for n, data in files.items():
        (tmp_path / n).write_bytes(data)
    (tmp_path / name).unlink()
    os.mkfifo(tmp_path / name)
    run = subprocess.run(
        [sys.executable, "-m", "gbviewer", "info", str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 2 and run.stderr.strip().splitlines() == [
        f"gbviewer: error: {tmp_path}: field '{name}': cannot read it (not a regular file)"
    ]
