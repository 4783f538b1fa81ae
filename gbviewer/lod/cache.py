"""The hierarchy's disk cache: one uncompressed .npz per scene content in the user cache folder
(platformdirs: ~/.cache/gbviewer/lod on Linux), keyed by a digest of the bytes the scene was loaded from
(Scene.content, hashed as the loader read them) and what the hierarchy depends on besides (splat count, SH layout,
the merge rule, the format version).
Written atomically; an entry is untrusted input (`entry.read_entry` checks it whole before use): one that does not
read back as a well-formed tree of the scene is rebuilt with one warning naming it. The folder holds at most
MAX_BYTES: a write drops the entries used longest ago (a read marks its entry used) until the rest fit."""

from __future__ import annotations

import hashlib
import os
import threading
import time
import warnings
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..core.errors import GBViewerError
from ..core.files import atomic_write
from ..model.scene import Scene
from .entry import read_entry
from .tree import Hierarchy, build

VERSION = 4  # of the tree layout and merge rules: bump when they change
MAX_BYTES = 4 << 30  # the folder's bound: the trees of about sixteen 6 M-splat scenes
STALE_TEMP_S = 3600  # a hidden temporary file (atomic_write's) this old was left by a writer that died


def default_folder() -> Path:
    """The user's cache folder for hierarchies."""
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("gbviewer")) / "lod"


def cache_key(scene: Scene, rule: str) -> str | None:
    """The cache key of the scene's hierarchy: the digest of the bytes the scene was loaded from (Scene.content)
    and what the tree depends on besides; None for a scene that is not exactly a file's content (not loaded, or
    made from a loaded one by dataclasses.replace: no content; arrays made writable again: maybe edited)."""
    if scene.content is None or not scene.intact:
        return None
    ident = (
        f"v{VERSION}|{scene.content}|{scene.num_splats}|{scene.sh.shape[1]}|{scene.sh.dtype}|"
        f"{scene.filter_3d is not None}|{rule}"
    )
    return hashlib.sha256(ident.encode()).hexdigest()[:32]


def cached_build(scene: Scene, rule: str, folder: Path | None = None) -> Hierarchy:
    """The scene's hierarchy from the cache, else built (and written there when the folder can be written)."""
    with _working(scene):
        tree, write = _lookup(scene, rule, folder)
    write()
    return tree


def _lookup(scene: Scene, rule: str, folder: Path | None = None) -> tuple[Hierarchy, Callable[[], None]]:
    """The scene's hierarchy from the cache, else built; and what writes a built one there (nothing to write after
    a hit or for a scene that did not come from a file)."""
    key = cache_key(scene, rule)
    if key is None:
        return build(scene, rule), _nothing
    entry = (folder or default_folder()) / f"{key}.npz"
    with _writing_lock:  # another scene of the same file whose tree is being written: that tree
        pending = _writing.get(entry)
    if pending is not None:
        try:
            pending.check(scene)
            return pending, _nothing
        except ValueError:  # not this scene's after all (a key collision): its own tree
            pass
    if entry.exists():
        _doing[scene] = "reading"
        try:
            tree = read_entry(entry, scene, rule)
            _touch(entry)
            return tree, _nothing
        except FileNotFoundError:  # pruned by another process meanwhile: a miss
            pass
        except Exception as exc:  # noqa: BLE001 - a damaged or hostile entry of any kind (entry.read_entry)
            warnings.warn(
                f"{entry}: damaged level-of-detail cache entry ({type(exc).__name__}: {exc}); rebuilt", stacklevel=3
            )  # hierarchy_for or cached_build's caller
    _doing[scene] = "building"
    tree = build(scene, rule)
    try:
        tree.check(scene)
    except ValueError:  # values beyond float32 (a scene near its limits): it would not read back, so is not kept
        return tree, _nothing
    with _writing_lock:
        if entry in _writing:  # built meanwhile by another scene of the file: its write serves both
            return tree, _nothing
        _writing[entry] = tree
    return tree, lambda: _store(entry, tree)


def _nothing() -> None:
    pass


def _store(entry: Path, tree: Hierarchy) -> None:
    """Write `tree` as the cache entry `entry` (atomically), then prune the folder; a read-only cache is left be.
    Until it is written, lookups of the entry get `tree` (_writing)."""
    try:
        atomic_write(entry, lambda tmp: np.savez(tmp, **tree.arrays()), force=True)
        prune(entry.parent, keep=entry)
    except (OSError, GBViewerError):  # a read-only cache: the tree still serves this run
        pass
    finally:
        with _writing_lock:
            _writing.pop(entry, None)


def _touch(entry: Path) -> None:
    """Mark an entry used now (its mtime: the eviction order); one pruned meanwhile is not made again."""
    try:
        os.utime(entry)
    except OSError:
        pass


def prune(folder: Path, keep: Path) -> None:
    """Drop the entries used longest ago until the folder's entries fit in MAX_BYTES (never `keep`, so one entry
    larger than the bound stays) and temporary files left for over STALE_TEMP_S (not another writer's current one)."""
    entries = []
    for p in folder.glob("*.npz"):
        try:
            st = p.stat()
        except OSError:  # removed meanwhile (another process pruning)
            continue
        if not p.name.startswith("."):
            entries.append((st.st_mtime_ns, st.st_size, p))
        elif time.time() - st.st_mtime > STALE_TEMP_S:  # a crashed writer's
            _remove(p)
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= MAX_BYTES:
            break
        if p != keep and _remove(p):
            total -= size


def _remove(p: Path) -> bool:
    """Remove a cache file; False when it may not be (not ours: the next may be)."""
    try:
        p.unlink(missing_ok=True)
        return True
    except OSError:
        return False


_writing: dict[Path, Hierarchy] = {}  # entries being written, and their trees
_writing_lock = threading.Lock()
_memo: "weakref.WeakKeyDictionary[Scene, dict[str, Hierarchy]]" = weakref.WeakKeyDictionary()
_lock = threading.Lock()
_doing: "weakref.WeakKeyDictionary[Scene, str]" = weakref.WeakKeyDictionary()  # what hierarchy_for does for a scene


def hierarchy_state(scene: Scene, rule: str = "depth") -> str:
    """Where the scene's hierarchy is, without waiting for it: "ready" (`hierarchy_for` returns it at once),
    "reading" (from the cache), "building", or "" (not asked for)."""
    if rule in _memo.get(scene, {}):
        return "ready"
    return _doing.get(scene, "")


@contextmanager
def _working(scene: Scene) -> Iterator[None]:
    """While a hierarchy of `scene` is looked up or built (`_lookup` says which: reading, building)."""
    _doing[scene] = "building"
    try:
        yield
    finally:
        _doing.pop(scene, None)


def hierarchy_for(scene: Scene, rule: str = "depth", cache: bool = True) -> Hierarchy:
    """The scene's hierarchy: built once per Scene object (the first caller builds, others wait), read from or
    written to the user cache when the scene came from a file and `cache` is true. The builder writes the cache
    entry after handing the tree over, so that callers waiting for it (the viewer's previews) do not wait for the
    write too; a write that raises (other than for a read-only cache) is not remembered: the next call builds
    again. A scene whose arrays may have been edited since (`Scene.intact`) gets a tree built anew, kept nowhere."""
    if not scene.intact:
        return build(scene, rule)
    with _lock:
        per_scene = _memo.setdefault(scene, {})
        if rule in per_scene:
            return per_scene[rule]
        with _working(scene):
            tree, write = _lookup(scene, rule) if cache else (build(scene, rule), _nothing)
        per_scene[rule] = tree
    try:
        write()
    except BaseException:  # a write that fails other than as a read-only cache (_store): this call leaves nothing
        with _lock:
            if per_scene.get(rule) is tree:
                del per_scene[rule]
        raise
    return tree
