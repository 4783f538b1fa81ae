"""The level-of-detail disk cache (gbviewer.lod.cache): keyed by the bytes a scene was loaded from, a truncated entry
rebuilt with one warning, the entries used last kept within its bound, and a tree handed to waiting callers while
its builder writes the entry. Hostile entries: test_lod_cache_entries.py; the content key: test_lod_content_key.py."""

from __future__ import annotations

import os
import threading
import warnings

import numpy as np
import pytest
from helpers import random_scene

import gbviewer as gb
from gbviewer import lod
from gbviewer.io.write import write_inria_ply
from gbviewer.lod.cache import cache_key, cached_build


def test_cache_key_follows_the_file(tmp_path):
    path = write_inria_ply(random_scene(300, seed=8), tmp_path / "a.ply")
    scene = gb.load(path)
    key = cache_key(scene, "depth")
    assert key is not None and key == cache_key(gb.load(path), "depth") and key != cache_key(scene, "sum")
    write_inria_ply(random_scene(300, seed=9), path, force=True)
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    assert cache_key(gb.load(path), "depth") != key
    assert cache_key(random_scene(10), "depth") is None  # not from a file: built, never cached
    loaded = gb.load(path)
    write_inria_ply(random_scene(300, seed=10), path, force=True)  # rewritten after the load, same layout
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    # keyed by the bytes it was loaded from: its tree is the loaded splats', never the new file's
    key = cache_key(loaded, "depth")
    assert key is not None and key != cache_key(gb.load(path), "depth") is not None


def test_a_truncated_cache_entry_is_rebuilt_with_one_warning(tmp_path):
    path = write_inria_ply(random_scene(400, seed=10, sh_degree=1), tmp_path / "b.ply")
    scene = gb.load(path)
    cache = tmp_path / "cache"
    first = cached_build(scene, "depth", cache)
    (entry,) = cache.glob("*.npz")
    data = entry.read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = cached_build(scene, "depth", cache)  # read back, no warning
    assert all(np.array_equal(a, b) for a, b in zip(first.arrays().values(), again.arrays().values()))
    entry.write_bytes(data[: len(data) // 2])
    with pytest.warns(UserWarning, match="damaged level-of-detail cache entry") as caught:
        rebuilt = cached_build(scene, "depth", cache)
    assert len(caught) == 1 and caught[0].filename == __file__  # pointed at the caller
    assert all(np.array_equal(a, b) for a, b in zip(first.arrays().values(), rebuilt.arrays().values()))
    assert entry.read_bytes() == data  # rewritten whole


def test_the_cache_keeps_the_entries_used_last_within_its_bound(tmp_path, monkeypatch):
    scenes = [gb.load(write_inria_ply(random_scene(300, seed=20 + i), tmp_path / f"s{i}.ply")) for i in range(3)]
    cache = tmp_path / "cache"
    cached_build(scenes[0], "depth", cache)
    (first,) = cache.glob("*.npz")
    monkeypatch.setattr(lod.cache, "MAX_BYTES", 2 * first.stat().st_size + 1)  # two entries fit
    cached_build(scenes[1], "depth", cache)
    os.utime(first, ns=(0, 0))  # used longest ago ...
    cached_build(scenes[0], "depth", cache)  # ... until read again
    writing, crashed = cache / ".other-writer.npz", cache / ".crashed-writer.npz"  # atomic_write's temporary names
    writing.write_bytes(b"x" * first.stat().st_size)  # not counted, not removed
    crashed.write_bytes(b"x")
    os.utime(crashed, ns=(0, 0))  # left long ago: removed
    cached_build(scenes[2], "depth", cache)
    names = {p.name for p in cache.glob("*.npz")}
    assert names == {f"{cache_key(scenes[i], 'depth')}.npz" for i in (0, 2)} | {writing.name}


def hold_cache_writes(monkeypatch, folder) -> tuple[threading.Event, threading.Event]:
    """The cache in `folder`, its writes held: (set when a write starts, set it to let the write go on)."""
    monkeypatch.setattr(lod.cache, "default_folder", lambda: folder)
    writing, release, store = threading.Event(), threading.Event(), lod.cache._store

    def slow_store(entry, tree):
        writing.set()
        assert release.wait(10)
        store(entry, tree)

    monkeypatch.setattr(lod.cache, "_store", slow_store)
    return writing, release


def test_a_waiting_caller_gets_the_tree_while_the_builder_writes_the_cache(tmp_path, monkeypatch):
    """hierarchy_for hands a built tree over before its cache entry is written (the viewer's previews wait for the
    tree, not for the write); the builder's call returns once the entry is in place."""
    scene = gb.load(write_inria_ply(random_scene(300, seed=30), tmp_path / "w.ply"))
    writing, release = hold_cache_writes(monkeypatch, tmp_path / "cache")
    built: list = []
    builder = threading.Thread(target=lambda: built.append(lod.hierarchy_for(scene)))
    builder.start()
    assert writing.wait(10)
    waiting = lod.hierarchy_for(scene)  # while the builder is held in its write
    assert not list((tmp_path / "cache").glob("*.npz"))
    release.set()
    builder.join(10)
    assert built == [waiting] and len(list((tmp_path / "cache").glob("*.npz"))) == 1


def test_a_second_scene_of_the_file_gets_the_tree_being_written(tmp_path, monkeypatch):
    """Two loads of one file (a reload): while the first's tree is written to a damaged entry's place, the second
    gets that tree, with no second build and no second warning; a use of an entry pruned meanwhile makes no file."""
    path = write_inria_ply(random_scene(300, seed=31), tmp_path / "r.ply")
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / f"{cache_key(gb.load(path), 'depth')}.npz").write_bytes(b"PK damaged")
    writing, release = hold_cache_writes(monkeypatch, cache)
    build, builds = lod.cache.build, []
    monkeypatch.setattr(lod.cache, "build", lambda scene, rule: builds.append(scene) or build(scene, rule))
    first, second = gb.load(path), gb.load(path)
    built: list = []
    with pytest.warns(UserWarning, match="damaged level-of-detail cache entry") as caught:
        builder = threading.Thread(target=lambda: built.append(lod.hierarchy_for(first)))
        builder.start()
        assert writing.wait(10)
        again = lod.hierarchy_for(second)
        release.set()
        builder.join(10)
    assert len(caught) == 1 and len(builds) == 1 and builds[0] is first and built == [again]
    (entry,) = cache.glob("*.npz")
    entry.unlink()
    lod.cache._touch(entry)
    assert not entry.exists()
