"""Decompression and allocation bombs: small files whose headers claim huge contents are refused before the
memory is spent (peak RSS of a fresh process measured against loading a valid scene of the same format)."""

from __future__ import annotations

import gzip
import io
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import zstandard
from encoders import encode_spz, random_params, sog_files
from PIL import Image

import gbviewer as gb
from gbviewer.core.errors import SceneFormatError

PEAK = """
import resource, sys
import gbviewer as gb
try:
    gb.load(sys.argv[1])
    print("ok", end=" ")
except gb.GBViewerError as exc:
    print("error", end=" ")
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
"""
BUDGET_MB = 64  # above what loading a valid 300-splat scene peaks at


def load_peak_mb(path) -> tuple[str, int]:
    """Outcome and peak RSS (MiB) of loading `path` in a fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", PEAK, str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    outcome, mb = out.stdout.split()
    return outcome, int(mb)


def _zip(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return buf.getvalue()


def _png(width: int, height: int) -> bytes:
    buf = io.BytesIO()
    Image.new("RGBA", (width, height), (0, 0, 0, 255)).save(buf, format="PNG")
    return buf.getvalue()


def bombs() -> dict[str, bytes]:
    s = random_params(300, seed=1)
    sog = sog_files(s)
    big_image = dict(sog, **{"sh0.webp": _png(6000, 6000)})  # 36 M pixels for 300 splats: ~1 MB of PNG
    big_meta = dict(sog, **{"meta.json": sog["meta.json"] + b" " * (64 << 20)})  # 64 MB of JSON from ~64 KB
    # 20 M splats of SH degree 0 declared, then 64 MB of zeros: gzip makes ~64 KB of it
    spz_gzip = gzip.compress(struct.pack("<4sIIBBBB", b"NGSP", 2, 20_000_000, 0, 12, 0, 0) + bytes(64 << 20))
    header = struct.pack("<4sIIBBBBI12x", b"NGSP", 4, 20_000_000, 0, 12, 0, 5, 32)
    zstd = zstandard.ZstdCompressor().compress(bytes(60_000_000))  # one stream of the declared size
    spz_zstd = header + struct.pack("<QQ", len(zstd), 60_000_000) * 5 + zstd
    return {
        "sog_image": _zip(big_image),
        "sog_meta": _zip(big_meta),
        "spz_gzip": spz_gzip,
        "spz_zstd": spz_zstd,
        "valid_sog": _zip(sog),
        "valid_spz": encode_spz(s, 2),
    }


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bombs")
    paths = {}
    for name, data in bombs().items():
        paths[name] = folder / name
        paths[name].write_bytes(data)
    return paths


@pytest.mark.parametrize(
    "name,match",
    [
        ("sog_image", "6000x6000"),
        ("sog_meta", "meta.json"),
        ("spz_gzip", "compressed bytes"),
        ("spz_zstd", "compressed bytes"),
    ],
)
def test_bomb_is_refused_with_one_line(files, name, match):
    assert files[name].stat().st_size < 2 << 20
    with pytest.raises(SceneFormatError, match=match) as err:
        gb.load(files[name])
    assert "\n" not in str(err.value) and str(files[name]) in str(err.value)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,valid",
    [("sog_image", "valid_sog"), ("sog_meta", "valid_sog"), ("spz_gzip", "valid_spz"), ("spz_zstd", "valid_spz")],
)
def test_bomb_peak_memory_stays_near_a_valid_load(files, name, valid):
    ok, base = load_peak_mb(files[valid])
    assert ok == "ok"
    outcome, peak = load_peak_mb(files[name])
    assert outcome == "error"
    assert peak < base + BUDGET_MB, f"{name}: peak {peak} MiB vs {base} MiB for a valid file"


def test_sog_image_budget_allows_power_of_two_padding(tmp_path):
    """The pixel budget is not so tight that a writer padding every image to a power-of-two texture is refused."""
    files = sog_files(random_params(300, seed=2))
    padded = {}
    for name, data in files.items():
        if name.endswith(".webp"):
            pixels = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA")).reshape(-1, 4)[:300]
            square = np.zeros((64 * 64, 4), np.uint8)
            square[:300] = pixels
            buf = io.BytesIO()
            Image.fromarray(square.reshape(64, 64, 4), "RGBA").save(buf, format="PNG")
            padded[name] = buf.getvalue()  # 4096 pixels for 300 splats
    (tmp_path / "a.sog").write_bytes(_zip(files))
    (tmp_path / "b.sog").write_bytes(_zip(dict(files, **padded)))
    a, b = gb.load(tmp_path / "a.sog"), gb.load(tmp_path / "b.sog")
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_array_equal(a.sh, b.sh)


SEED_PLY = Path(__file__).parent / "fuzz" / "seeds" / "inria"


@pytest.mark.parametrize(
    "seed,element,count",
    [
        ("sh1.ply", "vertex", "99999999999999999999"),  # does not fit an index
        ("sh1.ply", "vertex", str(2**40)),
        ("ascii.ply", "vertex", str(2**40)),
        ("sh1.ply", "junk", str(2**40)),  # an extra element after the vertices
        ("sh1.ply", "vertex", "-3"),
        ("sh1.ply", "vertex", "1e3"),
    ],
)
def test_ply_declared_counts_are_checked_against_the_bytes_present(tmp_path, seed, element, count):
    head, body = (SEED_PLY / seed).read_bytes().split(b"end_header\n", 1)
    if element == "vertex":
        head = head.replace(b"element vertex 12", f"element vertex {count}".encode())
    else:
        head += f"element {element} {count}\nproperty uchar v\n".encode()
    path = tmp_path / "bad.ply"
    path.write_bytes(head + b"end_header\n" + body)
    with pytest.raises(SceneFormatError, match=f"field '{element}': ") as err:
        gb.load(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("seed", ["sh1.ply", "ascii.ply"])
def test_ply_elements_after_the_vertices_are_not_read(tmp_path, monkeypatch, seed):
    """A mesh's faces after the splats (list properties plyfile would parse row by row into memory) are skipped."""
    import plyfile

    head, body = (SEED_PLY / seed).read_bytes().split(b"end_header\n", 1)
    binary = b"binary" in head
    faces = (struct.pack("<Biii", 3, 0, 1, 2) if binary else b"3 0 1 2\n") * 100
    path = tmp_path / "mesh.ply"
    path.write_bytes(head + b"element face 100\nproperty list uchar int vertex_indices\nend_header\n" + body + faces)
    read = []
    original = plyfile.PlyElement._read
    monkeypatch.setattr(
        plyfile.PlyElement, "_read", lambda self, *a, **k: (read.append(self.name), original(self, *a, **k))[1]
    )
    scene = gb.load(path)
    assert scene.num_splats == 12 and read == ([] if binary else ["vertex"])  # binary: streamed, plyfile reads none
    np.testing.assert_array_equal(scene.means, gb.load(SEED_PLY / seed).means)


def test_ply_without_splat_elements_is_one_line(tmp_path):
    path = tmp_path / "faces.ply"
    path.write_bytes(
        b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n3 0 1 2\n"
    )
    with pytest.raises(SceneFormatError, match="vertex") as err:
        gb.load(path)
    assert "\n" not in str(err.value)
