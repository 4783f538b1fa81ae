"""The splat hierarchy: an 8-ary tree over the Morton order of the splat centres, built natively (native/cpu/lod.cpp).

Nodes are numbered flat: 0..N-1 the leaves in Morton order (leaf p is splat `order[p]`), then the interior nodes
level by level up to the root (`levels[l]..levels[l+1]` are level l's ids). Interior node q of level l has the
children `levels[l-1] + 8 (q - levels[l])` up to that level's end; its parent follows the same way. The interior
arrays (`means` ... `size`) are indexed by id - N.

Merge rule (float64): a leaf of opacity a and scales s weighs w = a A, A = pi/3 (s1 s2 + s2 s3 + s1 s3) (the mean
of its principal cross-sections: opacity x area, as Hierarchical 3DGS weights children). A node's mean, covariance
(the second central moment of the w-weighted mixture of its leaves), SH and 3D filter are the w-weighted means of
its leaves'; its opacity keeps the leaves' area-weighted optical depth, -ln(1 - alpha) A_node = sum -ln(1 - a) A
(two identical children: alpha = 1 - (1 - a)^2, what compositing them gives), or with `rule="sum"` the covered area,
alpha A_node = sum a A. `rule="opacity"` is "depth" with the leaves weighted by a alone (measured against, not
used). `radius`: a sphere about the mean holding every leaf's centre; `size`: the merged Gaussian's world
footprint, 2 sqrt(largest eigenvalue). A light, wide child may be larger than its parent, which then stands for it
in the cut (taking the largest child's size instead draws far more nodes at zoom-out and loses PSNR against the
zoom-out reference; bench/RESULTS.md).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..core.errors import GBViewerError
from ..model.scene import MAX_SH, Scene

RULES = ("depth", "sum", "opacity")  # lod.h OpacityRule, in its order
BRANCHING = 8
INTERIOR = ("means", "scales", "quats", "opacities", "sh", "radius", "size")
QUAT_NORM_TOLERANCE = 1e-4  # |q|^2 - 1 of a built node's float32 unit quaternion is within a few float32 eps


@dataclass(frozen=True, eq=False)
class Hierarchy:
    """A scene's splat hierarchy (see the module docstring); filter_3d only for scenes with a 3D filter."""

    order: np.ndarray  # (N,) int32
    levels: np.ndarray  # (L+1,) int64
    means: np.ndarray  # (M,3) float32
    scales: np.ndarray  # (M,3)
    quats: np.ndarray  # (M,4)
    opacities: np.ndarray  # (M,)
    sh: np.ndarray  # (M,K,3)
    radius: np.ndarray  # (M,)
    size: np.ndarray  # (M,)
    filter_3d: np.ndarray | None = None
    rule: str = "depth"
    build_ms: float = 0.0

    def __post_init__(self) -> None:
        for name, a in self.arrays().items():  # read-only views: a tree is shared by every render of its scene
            view = a.view()
            view.flags.writeable = False
            object.__setattr__(self, name, view)

    @property
    def num_leaves(self) -> int:
        return int(self.levels[1])

    @property
    def num_interior(self) -> int:
        return int(self.levels[-1] - self.levels[1])

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays the hierarchy adds to the scene's."""
        return sum(getattr(self, f.name).nbytes for f in fields(self) if isinstance(getattr(self, f.name), np.ndarray))

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays by name (filter_3d only when present)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        return {k: v for k, v in out.items() if isinstance(v, np.ndarray)}

    def children(self, node: int) -> range:
        """The ids of an interior node's children (flat ids)."""
        lv = self.levels
        level = int(np.searchsorted(lv, node, side="right")) - 1
        if level < 1:
            raise GBViewerError(f"node {node} is a leaf")
        first = int(lv[level - 1]) + BRANCHING * (node - int(lv[level]))
        return range(first, min(first + BRANCHING, int(lv[level])))

    def check(self, scene: Scene) -> None:
        """Raise ValueError unless the tree is a well-formed hierarchy of `scene`'s layout, as `build` makes them:
        the arrays' dtypes and shapes (`layout`), the levels, `order` a permutation of the splats, every value
        finite, scales, radius, size and filter_3d >= 0, opacities in [0, 1], unit quaternions, SH within MAX_SH.
        What the cut and the renderers index with or draw is checked before they see it: a cache entry is
        untrusted input (another version, a crash, a copy or anyone may have written it)."""
        want = layout(scene)
        arrays = self.arrays()
        if set(arrays) != set(want):
            raise ValueError(f"arrays {sorted(arrays)}, expected {sorted(want)}")
        for name, (shape, dtype) in want.items():
            a = arrays[name]
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(f"{name} is {a.dtype} {a.shape}, expected {np.dtype(dtype)} {shape}")
        if self.levels.tolist() != level_offsets(scene.num_splats):
            raise ValueError("levels do not match the scene's splat count")
        n = scene.num_splats
        if self.order.min() < 0 or self.order.max() >= n:
            raise ValueError("order holds indices outside the scene")
        seen = np.zeros(n, bool)
        seen[self.order] = True
        if not seen.all():
            raise ValueError("order is not a permutation of the splats (an index repeats)")
        for name in ("means", "scales", "quats", "opacities", "sh", "radius", "size", "filter_3d"):
            if name in arrays and not np.isfinite(arrays[name]).all():
                raise ValueError(f"{name} holds values that are not finite")
        for name in ("scales", "radius", "size", "filter_3d"):
            if name in arrays and (arrays[name] < 0).any():
                raise ValueError(f"{name} holds negative values")
        if ((self.opacities < 0) | (self.opacities > 1)).any():
            raise ValueError("opacities outside [0, 1]")
        if (np.abs(np.einsum("ij,ij->i", self.quats, self.quats) - 1) > QUAT_NORM_TOLERANCE).any():
            raise ValueError("quats are not unit quaternions")
        if (np.abs(self.sh) > np.float32(MAX_SH)).any():
            raise ValueError(f"sh holds values beyond {MAX_SH:g}")


def level_offsets(n: int) -> list[int]:
    """The levels of a hierarchy of n splats: 0, n, then ceil(count / 8) more nodes per level up to one root."""
    offsets, count = [0, n], n
    while count > 1:
        count = -(-count // BRANCHING)
        offsets.append(offsets[-1] + count)
    return offsets


def layout(scene: Scene) -> dict[str, tuple[tuple[int, ...], str]]:
    """The (shape, dtype) of each array of `scene`'s hierarchy (filter_3d only for a scene with a 3D filter)."""
    levels = level_offsets(scene.num_splats)
    n, m, k = scene.num_splats, levels[-1] - levels[1], scene.sh.shape[1]
    out = {
        "order": ((n,), "int32"),
        "levels": ((len(levels),), "int64"),
        "means": ((m, 3), "float32"),
        "scales": ((m, 3), "float32"),
        "quats": ((m, 4), "float32"),
        "opacities": ((m,), "float32"),
        "sh": ((m, k, 3), "float32"),
        "radius": ((m,), "float32"),
        "size": ((m,), "float32"),
    }
    if scene.filter_3d is not None:
        out["filter_3d"] = ((m,), "float32")
    return out


def build(scene: Scene, rule: str = "depth", threads: int = 0) -> Hierarchy:
    """Build the hierarchy of `scene` (float16 SH: merged from a float32 copy)."""
    import time

    from .._native import lod as native

    if rule not in RULES:
        raise GBViewerError(f"LOD opacity rule {rule!r}; expected one of {RULES}")
    if not scene.num_splats:
        raise GBViewerError(f"{scene.source}: no splats to build a level-of-detail hierarchy of")
    t0 = time.perf_counter()
    out = native.build(
        scene.means,
        scene.scales,
        scene.quats,
        scene.opacities,
        np.ascontiguousarray(scene.sh, np.float32),
        scene.filter_3d,
        RULES.index(rule),
        threads,
    )
    return Hierarchy(rule=rule, build_ms=(time.perf_counter() - t0) * 1e3, **out)
