"""The hierarchy cache keys on the content a scene came from: a digest of every byte its loader read (each file of
a multi-file format too), hashed as they were read; a scene that is not exactly its file's content (replaced or
edited arrays) is never stored or fetched under the file's key."""

from __future__ import annotations

import dataclasses
import os
import zipfile

import numpy as np
import pytest
from helpers import random_scene
from PIL import Image

import gbviewer as gb
from gbviewer import lod
from gbviewer.io import ply_stream
from gbviewer.io.progress import ContentDigest
from gbviewer.io.write import write_inria_ply
from gbviewer.lod.cache import cache_key, cached_build

SEEDS = "tests/io/fuzz/seeds"


def same_trees(a: lod.Hierarchy, b: lod.Hierarchy) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a.arrays().values(), b.arrays().values()))


def writable(a: np.ndarray) -> None:
    """Set the WRITEABLE flag of `a` and of every array it is a view of (bases first)."""
    if isinstance(a.base, np.ndarray):
        writable(a.base)
    a.flags.writeable = True


def rewrite_keeping_stat(path, edit) -> None:
    """Change the file's bytes in place, its size and mtime as they were (as `cp -p`, `rsync -a`, `tar` leave a
    file)."""
    st = os.stat(path)
    data = bytearray(path.read_bytes())
    edit(data)
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert os.stat(path).st_size == st.st_size


@pytest.mark.parametrize(
    "name",
    [
        "inria/sh1.ply",
        "inria/ascii.ply",
        "compressed/sh1.ply",
        "spz/v2.spz",
        "spz/v3raw.spz",
        "spz/v4.spz",
        "splat/a.splat",
        "sog/a.sog",
    ],
)
def test_every_format_loads_with_a_content_digest(name):
    a, b = gb.load(f"{SEEDS}/{name}"), gb.load(f"{SEEDS}/{name}")
    assert a.content is not None and a.content == b.content
    assert cache_key(a, "depth") == cache_key(b, "depth") != cache_key(a, "sum")


def test_a_same_size_change_past_64_kib_with_the_mtime_restored_is_a_new_key(tmp_path):
    path = write_inria_ply(random_scene(3000, seed=1, sh_degree=1), tmp_path / "a.ply")
    assert path.stat().st_size > 3 << 16
    cache = tmp_path / "cache"
    old = cached_build(gb.load(path), "depth", cache)
    row = (path.stat().st_size - (3 << 16)) // 4 * 4  # a float near the end, past the first 64 KiB
    rewrite_keeping_stat(path, lambda d: d.__setitem__(slice(row, row + 4), np.float32(7.5).tobytes()))
    scene = gb.load(path)
    tree = cached_build(scene, "depth", cache)
    assert same_trees(tree, lod.build(scene)) and not same_trees(tree, old)
    assert len(list(cache.glob("*.npz"))) == 2


def test_a_sog_read_through_meta_json_keys_on_its_images_too(tmp_path):
    with zipfile.ZipFile(f"{SEEDS}/sog/a.sog") as z:
        z.extractall(tmp_path / "sog")
    meta = tmp_path / "sog" / "meta.json"
    cache = tmp_path / "cache"
    folder_scene, meta_scene = gb.load(tmp_path / "sog"), gb.load(meta)
    assert folder_scene.content == meta_scene.content is not None
    old = cached_build(meta_scene, "depth", cache)
    image = tmp_path / "sog" / "means_l.webp"
    with Image.open(image) as im:
        pixels = np.array(im)
    pixels[0, 0, :3] ^= 0x55  # another position for the first splat
    Image.fromarray(pixels).save(image, lossless=True)
    edited = gb.load(meta)
    assert edited.content != meta_scene.content and not np.array_equal(edited.means, meta_scene.means)
    tree = cached_build(edited, "depth", cache)
    assert same_trees(tree, lod.build(edited)) and not same_trees(tree, old)


def test_a_replaced_or_reopened_scene_is_never_stored_under_its_files_key(tmp_path):
    path = write_inria_ply(random_scene(400, seed=2, sh_degree=1), tmp_path / "e.ply")
    cache = tmp_path / "cache"
    scene = gb.load(path)
    flipped = dataclasses.replace(scene, sh=-scene.sh)
    renamed = dataclasses.replace(scene, source="elsewhere")  # the same arrays: still not the loaded Scene
    assert flipped.content is None and renamed.content is None and cache_key(flipped, "depth") is None
    cached_build(flipped, "depth", cache)
    assert not cache.exists()  # built, not stored
    edited = gb.load(path)
    writable(edited.sh)  # made writable again, deliberately: its arrays may no longer be the file's
    edited.sh[:] *= -1
    assert cache_key(edited, "depth") is None
    cached_build(edited, "depth", cache)
    assert not cache.exists()
    fresh = gb.load(path)
    assert same_trees(cached_build(fresh, "depth", cache), lod.build(fresh))


def test_the_parallel_loader_digest_does_not_depend_on_its_workers(tmp_path, monkeypatch):
    path = write_inria_ply(random_scene(20000, seed=3, sh_degree=3), tmp_path / "p.ply")
    monkeypatch.setattr(ply_stream, "SCATTER_BYTES", 1 << 16)  # many blocks per range
    digests = set()
    for workers in (1, 3, 8):
        monkeypatch.setattr(ply_stream, "MAX_LOAD_WORKERS", workers)
        monkeypatch.setattr(os, "cpu_count", lambda: 8)
        digests.add(gb.load(path).content)
    assert len(digests) == 1 and None not in digests


def test_a_digest_of_pieces_that_do_not_tile_their_file_is_none():
    d = ContentDigest()
    d.add("", 0, b"abcd")
    d.add("", 8, b"ijkl")  # bytes 4..8 read without being recorded
    assert d.hexdigest() is None
    d = ContentDigest()
    d.add("", 4, b"efgh")  # recorded from another thread first: the same digest as in order
    d.add("", 0, b"abcd")
    e = ContentDigest()
    e.add("", 0, b"abcd")
    e.add("", 4, b"efgh")
    assert d.hexdigest() == e.hexdigest() is not None
    e.add("", 4, b"EFGH")  # the same bytes read twice differently
    assert e.hexdigest() is None
