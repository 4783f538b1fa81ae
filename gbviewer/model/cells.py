"""Duplex-GS cells: ellipsoids that group splats, so that only cells are depth-sorted (docs/modes.md#duplex).

A trained Duplex-GS checkpoint has its own cells (the anchors, decoded per view by `gbviewer.io.duplex_model`). Any
other scene gets cells built once, on first use, by `build_cells`:

- Grouping: a k-d partition of the splat centres. Every group is split at a multiple of K along the longest axis of
  its bounding box (its coordinate median, rounded to a multiple of K) until groups have at most K splats, so all
  cells hold exactly K splats except one. Vectorised over all groups of a level (one argsort per level,
  ~log2(N/K) levels). K defaults to 5, Duplex-GS's NUM_GS_PER_ANCHOR (each trained cell emits 5 neural
  Gaussians), so that the sort-length reduction is measured at the granularity the paper's Table VI reports.
- Ellipsoid: centre = mean of the members' centres; axes = eigenvectors of the members' second moment about the
  centre including their own covariances, (1/K) sum_i (d_i d_i^T + Sigma_i); per axis u the half extent
  e = max_i (|d_i . u| + 3 sqrt(u^T Sigma_i u)) bounds every member's 3-sigma ellipsoid by the box [-e, e]. The cell's
  2-sigma ellipsoid (Duplex-GS projects cells with radius 2 sqrt(lambda1), splats with 3 sqrt(lambda1)) gets the
  semi-axes lambda e with the smallest lambda that contains every member's 3-sigma ellipsoid, bounded through the
  triangle inequality: lambda = max_i (|D^-1 d_i| + 3 |D^-1 L_i|_2), D = diag(e), Sigma_i = L_i L_i^T in the cell
  frame; lambda <= sqrt(3) (the box's circumscribed ellipsoid). scales = lambda e / 2. So a cell's tile rectangle
  covers its splats' up to projection approximations; the renderer counts the splat-tile pairs it misses
  (FrameStats.cell_misses).
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import GBViewerError

DEFAULT_CELL_SIZE = 5  # splats per cell for scenes without cells (Duplex-GS NUM_GS_PER_ANCHOR)
COVER_SIGMAS = 3.0  # members are covered out to their 3-sigma ellipsoid (the splat radius of the blend)


@dataclass(frozen=True, eq=False)
class Cells:
    """M cells over the N splats of a scene. Cell c holds splats members[offsets[c]:offsets[c+1]].

    means (M,3), scales (M,3) (activated; the 1-sigma ellipsoid), quats (M,4) unit (w,x,y,z), offsets (M+1,) int32,
    members (<= N,) int32. `origin` says where they came from, `build_ms` how long building took.

    The cells must partition splats: offsets rise from 0 to len(members), members are distinct splat indices. The
    shapes and offsets are checked on construction (arrays become float32 / int32, C-contiguous), the members against
    the scene by `validate(num_splats)`, which `cells_for` calls for every backend: the renderers index with them
    unchecked on the device. Violations raise GBViewerError.
    """

    means: np.ndarray
    scales: np.ndarray
    quats: np.ndarray
    offsets: np.ndarray
    members: np.ndarray
    origin: str = ""
    build_ms: float = 0.0
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("means", "scales", "quats"):
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), np.float32))
        for name in ("offsets", "members"):
            a = np.asarray(getattr(self, name))
            if a.ndim != 1 or (a.size and a.dtype.kind not in "iu"):
                raise GBViewerError(f"{self._name}: {name} must be a 1-D integer array, got {a.dtype} {a.shape}")
            if a.size and (a.min() < 0 or a.max() > np.iinfo(np.int32).max):
                raise GBViewerError(f"{self._name}: {name} must lie in 0..2^31-1, got {a.min()}..{a.max()}")
            object.__setattr__(self, name, np.ascontiguousarray(a, np.int32))
        m = self.means.shape[0] if self.means.ndim == 2 else -1
        if m < 0 or self.means.shape != (m, 3) or self.scales.shape != (m, 3) or self.quats.shape != (m, 4):
            raise GBViewerError(
                f"{self._name}: means and scales must be (M,3), quats (M,4); got "
                f"{self.means.shape}, {self.scales.shape}, {self.quats.shape}"
            )
        off = self.offsets
        if off.shape != (m + 1,) or off[0] != 0 or off[-1] != len(self.members) or (np.diff(off) < 0).any():
            raise GBViewerError(
                f"{self._name}: offsets must be {m + 1} non-decreasing values from 0 to "
                f"len(members) = {len(self.members)}"
            )
        for name in ("means", "scales", "quats", "offsets", "members"):  # checked once (validate), then trusted
            view = getattr(self, name).view()
            view.flags.writeable = False
            object.__setattr__(self, name, view)

    @property
    def _name(self) -> str:
        return f"cells ({self.origin})" if self.origin else "cells"

    def validate(self, num_splats: int) -> "Cells":
        """Check that the members are distinct splats of a scene of num_splats (once per size); returns self."""
        if getattr(self, "_valid_for", None) == num_splats:
            return self
        mem = self.members
        if len(mem) and mem.max() >= num_splats:
            raise GBViewerError(
                f"{self._name}: member index {int(mem.max())} outside the scene's splats 0..{num_splats - 1}"
            )
        if len(mem) and np.bincount(mem, minlength=num_splats).max() > 1:
            raise GBViewerError(
                f"{self._name}: a splat is listed more than once in members (each splat belongs to at most one cell)"
            )
        object.__setattr__(self, "_valid_for", num_splats)
        return self

    @property
    def num_cells(self) -> int:
        return int(self.means.shape[0])

    @property
    def sizes(self) -> np.ndarray:
        return np.diff(self.offsets)

    def cell_of(self, num_splats: int) -> np.ndarray:
        """Each splat's cell (int32, -1: in none), for a scene of num_splats."""
        out = np.full(num_splats, -1, np.int32)
        out[self.members] = np.repeat(np.arange(self.num_cells, dtype=np.int32), self.sizes)
        return out

    def stats(self) -> dict:
        """Cell count, members per cell (mean, min, max), splats per cell ratio, build time, origin."""
        sizes = self.sizes
        out = {
            "origin": self.origin,
            "cells": self.num_cells,
            "splats": int(sizes.sum()),
            "members_mean": float(sizes.mean()) if len(sizes) else 0.0,
            "members_min": int(sizes.min()) if len(sizes) else 0,
            "members_max": int(sizes.max()) if len(sizes) else 0,
            "build_ms": self.build_ms,
        }
        out.update(self.info)
        return out

    @classmethod
    def from_groups(
        cls,
        means,
        scales,
        quats,
        cell_of: np.ndarray,
        origin: str = "",
        build_ms: float = 0.0,
        info: dict | None = None,
    ) -> "Cells":
        """Cells from per-splat cell indices (-1: in no cell); members keep their splat order."""
        cell_of = np.asarray(cell_of, np.int64)
        m = len(means)
        inside = np.flatnonzero(cell_of >= 0)
        order = inside[np.argsort(cell_of[inside], kind="stable")]
        counts = np.bincount(cell_of[inside], minlength=m)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        return cls(
            np.ascontiguousarray(means, np.float32),
            np.ascontiguousarray(scales, np.float32),
            np.ascontiguousarray(quats, np.float32),
            offsets,
            order.astype(np.int32),
            origin,
            build_ms,
            dict(info or {}),
        )


def kd_groups(points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Partition points (N,3) into spatially compact groups of at most k (all of exactly k but one).

    Returns (order, starts): points[order] lists the groups one after the other; group g is order[starts[g]:
    starts[g+1]] (starts has a final entry N)."""
    n = len(points)
    pts = np.asarray(points, np.float64)
    order = np.arange(n)
    starts = np.array([0], np.int64)
    sizes = np.array([n], np.int64)
    while (sizes > k).any():
        seg = np.repeat(np.arange(len(starts)), sizes)
        p = pts[order]
        lo = np.minimum.reduceat(p, starts, axis=0)
        hi = np.maximum.reduceat(p, starts, axis=0)
        ext = hi - lo
        axis = np.argmax(ext, axis=1)
        big = sizes > k
        coord = p[np.arange(n), axis[seg]]
        span = ext[np.arange(len(starts)), axis]
        frac = (coord - lo[seg, axis[seg]]) / np.where(span > 0, span, 1.0)[seg]
        key = seg + 0.5 * np.clip(frac, 0.0, 1.0) * big[seg]  # small groups keep their order
        order = order[np.argsort(key, kind="stable")]
        groups = -(-sizes // k)  # ceil(sizes / k)
        left = k * -(-groups // 2)  # a multiple of k near the middle
        new_starts = np.concatenate([starts, (starts + left)[big]])
        starts = np.sort(new_starts)
        sizes = np.diff(np.append(starts, n))
    return order, np.append(starts, n)


def quats_from_matrices(R: np.ndarray) -> np.ndarray:
    """(M,3,3) rotation matrices -> (M,4) unit quaternions (w,x,y,z) (Shepperd: the largest of w, x, y, z first)."""
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], 1)
    which = np.argmax(cand, 1)
    q = np.empty((len(R), 4))
    s = np.sqrt(np.maximum(1.0 + 2.0 * cand[np.arange(len(R)), which] - tr, 1e-30)) * 2.0  # 4 * |component|
    w = which == 0
    q[w] = np.stack(
        [
            0.25 * s[w],
            (R[w, 2, 1] - R[w, 1, 2]) / s[w],
            (R[w, 0, 2] - R[w, 2, 0]) / s[w],
            (R[w, 1, 0] - R[w, 0, 1]) / s[w],
        ],
        1,
    )
    x = which == 1
    q[x] = np.stack(
        [
            (R[x, 2, 1] - R[x, 1, 2]) / s[x],
            0.25 * s[x],
            (R[x, 0, 1] + R[x, 1, 0]) / s[x],
            (R[x, 0, 2] + R[x, 2, 0]) / s[x],
        ],
        1,
    )
    y = which == 2
    q[y] = np.stack(
        [
            (R[y, 0, 2] - R[y, 2, 0]) / s[y],
            (R[y, 0, 1] + R[y, 1, 0]) / s[y],
            0.25 * s[y],
            (R[y, 1, 2] + R[y, 2, 1]) / s[y],
        ],
        1,
    )
    z = which == 3
    q[z] = np.stack(
        [
            (R[z, 1, 0] - R[z, 0, 1]) / s[z],
            (R[z, 0, 2] + R[z, 2, 0]) / s[z],
            (R[z, 1, 2] + R[z, 2, 1]) / s[z],
            0.25 * s[z],
        ],
        1,
    )
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_matrices(quats: np.ndarray) -> np.ndarray:
    """(N,4) unit (w,x,y,z) -> (N,3,3), the same formula as the kernels' covariance_3d."""
    w, x, y, z = np.asarray(quats, np.float64).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def covering_ellipsoids(means, scales, quats, order: np.ndarray, starts: np.ndarray):
    """Centre, scales and rotation of the cell ellipsoid of each group (see the module docstring)."""
    p = np.asarray(means, np.float64)[order]
    Rm = rotation_matrices(np.asarray(quats)[order])
    M = Rm * np.asarray(scales, np.float64)[order][:, None, :]
    Sig = M @ M.transpose(0, 2, 1)
    st = starts[:-1]
    counts = np.diff(starts)
    seg = np.repeat(np.arange(len(st)), counts)
    centre = np.add.reduceat(p, st, axis=0) / counts[:, None]
    d = p - centre[seg]
    second = np.add.reduceat(d[:, :, None] * d[:, None, :] + Sig, st, axis=0) / counts[:, None, None]
    _, U = np.linalg.eigh(second)  # columns: axes
    U[:, :, 2] *= np.sign(np.linalg.det(U))[:, None]  # a proper rotation
    Us = U[seg]
    local = np.einsum("ni,nia->na", d, Us)  # member centres in the cell frame
    Sl = Us.transpose(0, 2, 1) @ Sig @ Us  # member covariances in the cell frame
    spread = np.sqrt(np.maximum(np.einsum("naa->na", Sl), 0.0))
    half = np.maximum.reduceat(np.abs(local) + COVER_SIGMAS * spread, st, axis=0)
    half = np.maximum(half, 1e-9 * np.maximum(half.max(axis=1, keepdims=True), 1e-30))
    # smallest lambda with every member's 3-sigma ellipsoid inside the ellipsoid of semi-axes lambda * half
    # (triangle inequality in the frame scaled by 1/half; lambda <= sqrt(3), the box's circumscribed ellipsoid)
    inv = 1.0 / half[seg]
    scaled = Sl * inv[:, :, None] * inv[:, None, :]
    widest = np.sqrt(np.maximum(np.linalg.eigvalsh(scaled)[:, -1], 0.0))
    reach = np.linalg.norm(local * inv, axis=1) + COVER_SIGMAS * widest
    lam = np.minimum(np.maximum.reduceat(reach, st), np.sqrt(3.0))
    return centre, 0.5 * lam[:, None] * half, quats_from_matrices(U)


def build_cells(scene, k: int = DEFAULT_CELL_SIZE) -> Cells:
    """Cells of about k splats for a scene without its own (k-d partition + covering ellipsoids)."""
    if not (isinstance(k, (int, np.integer)) and k >= 1):
        raise ValueError(f"cell size must be an integer >= 1, got {k!r}")
    t0 = time.perf_counter()
    order, starts = kd_groups(scene.means, int(k))
    centre, scales, quats = covering_ellipsoids(scene.means, scene.scales, scene.quats, order, starts)
    build_ms = (time.perf_counter() - t0) * 1e3
    splat_scale = float(np.median(scene.scales.max(axis=1)))
    cell_scale = float(np.median(scales.max(axis=1)))
    return Cells(
        centre.astype(np.float32),
        scales.astype(np.float32),
        quats.astype(np.float32),
        starts.astype(np.int32),
        order.astype(np.int32),
        f"k-d partition, K={k}",
        build_ms,
        {"median_cell_over_splat_scale": cell_scale / splat_scale if splat_scale > 0 else float("inf")},
    )


_cache: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def cells_for(scene, k: int = DEFAULT_CELL_SIZE) -> Cells:
    """The scene's own cells when it has them (trained Duplex-GS), else cells of k splats, built once and cached;
    validated against the scene (every backend takes its cells from here); built anew for a scene whose arrays may
    have been edited since (`Scene.intact`)."""
    cells = scene.oit.cells if scene.oit is not None else None
    if cells is None and not scene.intact:
        cells = build_cells(scene, k)
    elif cells is None:
        per_scene = _cache.setdefault(scene, {})
        if k not in per_scene:
            per_scene[k] = build_cells(scene, k)
        cells = per_scene[k]
    return cells.validate(scene.num_splats)
