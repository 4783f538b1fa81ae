"""A large scene's sparse stand-in: every k-th splat, each widened to cover the area of the k it stands for, for a
preview while the scene's hierarchy is not there yet (its build takes seconds on a large scene; this takes one
strided copy). Keeping 1 in k splats leaves each k times the volume to cover: its scales grow by the cube root of k
(compared by eye on the tiled 6.1 M-splat scene at 1/4 resolution: sqrt(k), the surface rule, blurred it to blobs).
A rough picture, not a level of detail: nothing is merged, and a pane says so."""

from __future__ import annotations

import math
import threading
import weakref

import numpy as np

from ..model.scene import Scene

STAND_IN_SPLATS = 200_000  # at most: a low-resolution preview of this many splats takes tenths of a second

_memo: "weakref.WeakKeyDictionary[Scene, Scene]" = weakref.WeakKeyDictionary()
_lock = threading.Lock()


def stride(num_splats: int, splats: int | None = None) -> int:
    """k: the stand-in keeps every k-th of `num_splats` splats, to keep at most `splats` (default STAND_IN_SPLATS);
    1: the scene is small enough as it is."""
    return max(1, math.ceil(num_splats / max(1, STAND_IN_SPLATS if splats is None else splats)))


def stand_in(scene: Scene, splats: int | None = None) -> Scene:
    """The scene's stand-in of at most `splats` splats (default STAND_IN_SPLATS; the scene itself when it has no
    more), made once per scene; meta["stand_in"] = k."""
    k = stride(scene.num_splats, splats)
    if k == 1:
        return scene
    with _lock:
        made = _memo.get(scene)
        if made is None or made.meta.get("stand_in") != k:
            pick = slice(0, None, k)
            made = Scene(
                np.ascontiguousarray(scene.means[pick]),
                np.ascontiguousarray(scene.scales[pick] * np.float32(k ** (1 / 3))),
                np.ascontiguousarray(scene.quats[pick]),
                np.ascontiguousarray(scene.opacities[pick]),
                np.ascontiguousarray(scene.sh[pick]),
                None if scene.filter_3d is None else np.ascontiguousarray(scene.filter_3d[pick]),
                source=scene.source,
                meta={**scene.meta, "stand_in": k},
            )
            _memo[scene] = made
    return made
