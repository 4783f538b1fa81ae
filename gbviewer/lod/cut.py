"""The cut through a scene's hierarchy for one camera, and the Scene of its splats.

A node's projected size is p = size f / (distance to its centre - radius) pixels (f the larger focal length; an
orthographic camera: size f; a camera inside the node's sphere: infinite). Walking down from the root, a node with
p <= tau is drawn in place of its subtree, one with p >= tau (1 + band) is replaced by its children, and in between
it is drawn with its opacity times 1 - o beside its children (times o), o = (p - tau) / (tau band): parents fade
into their children across the band instead of popping. Along every leaf's path the drawn weights sum to 1, so the
cut covers every leaf once. tau = 0 is the leaf set: the scene itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import GBViewerError, RenderCancelled
from ..model.camera import Camera
from ..model.scene import Scene
from .cache import hierarchy_for
from .tree import Hierarchy

DEFAULT_BAND = 1.0  # parents fade out between tau and 2 tau


@dataclass(frozen=True, eq=False)
class Cut:
    """The drawn nodes: leaves as splat indices, in the tree's (Morton) order or, when they are over half the
    splats, ascending; interior nodes as interior indices (id - N, ascending); each with its opacity multiplier in
    (0, 1]."""

    leaves: np.ndarray
    leaf_weights: np.ndarray
    nodes: np.ndarray
    node_weights: np.ndarray

    @property
    def num_drawn(self) -> int:
        return len(self.leaves) + len(self.nodes)


def check_tau(tau: float, what: str = "lod") -> float:
    """tau as a float, or a one-line GBViewerError naming `what`."""
    try:
        tau = float(tau)
    except (TypeError, ValueError):
        raise GBViewerError(f"{what} = {tau!r}; expected a number of pixels >= 0") from None
    if not np.isfinite(tau) or tau < 0:
        raise GBViewerError(f"{what} = {tau!r}; expected a finite number of pixels >= 0")
    return tau


def cut_view(camera: Camera, tau: float, band: float = DEFAULT_BAND) -> tuple:
    """The cut's inputs as the native modules take them: (tau, band, eye float32, larger focal length,
    orthographic). The CPU renderer draws the cut of the same tuple in place (RenderSettings.lod)."""
    return (
        check_tau(tau),
        float(band),
        np.asarray(camera.position, np.float32),
        float(max(camera.fx, camera.fy)),
        bool(camera.orthographic),
    )


def cut(
    tree: Hierarchy,
    camera: Camera,
    tau: float,
    band: float = DEFAULT_BAND,
    threads: int = 0,
    flag: np.ndarray | None = None,
) -> Cut:
    """The nodes drawn for `camera` at tau pixels (band 0: a hard cut, every weight 1). `flag`: a render's cancel
    flag (int64 array, RenderControl.flag), read while the cut runs: RenderCancelled once it is nonzero."""
    rows, weights, nl = _cut_of_view(tree, cut_view(camera, tau, band), threads, flag)
    return Cut(rows[:nl], weights[:nl], rows[nl:], weights[nl:])


def cut_rows(
    tree: Hierarchy, view: tuple, threads: int = 0, flag: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The cut of `view` (`cut_view`'s tuple) as a renderer draws it in place over the scene's rows followed by the
    tree's interior nodes (interior node q at row N + q): int32 rows in the order `cut_scene` gathers them, float32
    opacity multipliers. `flag`: as cut's."""
    rows, weights, nl = _cut_of_view(tree, view, threads, flag)
    rows[nl:] += tree.num_leaves
    return rows, weights


def _cut_of_view(tree: Hierarchy, view: tuple, threads: int, flag: np.ndarray | None) -> tuple:
    """The native cut's (rows, weights, leaves) for `cut_view`'s tuple; RenderCancelled once `flag` is set."""
    from .._native import lod as native

    tau, band, eye, focal, ortho = view
    out = native.cut(
        tree.means, tree.radius, tree.size, tree.levels, tree.order, eye, focal, ortho, tau, band, threads, flag
    )
    if out is None:
        raise RenderCancelled("render cancelled")
    return out


def check_plain(scene: Scene) -> None:
    """Refuse a scene level of detail does not apply to (one that carries wsr / duplex data)."""
    if scene.oit is not None:
        raise GBViewerError(
            f"{scene.source}: level of detail is for plain splat scenes; this one carries wsr / "
            "duplex data (view weights, cells or a trained model)"
        )


def cut_scene(
    scene: Scene,
    camera: Camera,
    tau: float,
    band: float = DEFAULT_BAND,
    threads: int = 0,
    rule: str = "depth",
    flag: np.ndarray | None = None,
) -> Scene:
    """The Scene of the cut through the hierarchy merged by `rule`: the drawn leaves' splats, then the drawn interior
    nodes' Gaussians (SH as the scene's), opacities times the weights; meta["lod"] = (drawn, of). The scene itself
    when the cut is its leaves. `flag`: as cut's."""
    check_plain(scene)
    tree = hierarchy_for(scene, rule)
    c = cut(tree, camera, tau, band, threads, flag)
    if not len(c.nodes) and len(c.leaves) == scene.num_splats:
        return scene
    from .._native import lod as native

    float_sh = scene.sh.dtype == np.float32
    src = {"means": scene.means, "scales": scene.scales, "quats": scene.quats, "opacities": scene.opacities}
    if float_sh:
        src["sh"] = scene.sh
    if scene.filter_3d is not None:
        src["filter_3d"] = scene.filter_3d
    out = native.gather(src, tree.arrays(), c.leaves, c.leaf_weights, c.nodes, c.node_weights, threads)
    if not float_sh:  # float16 SH stays float16
        out["sh"] = np.concatenate([scene.sh[c.leaves], tree.sh[c.nodes].astype(np.float16)])
    meta = {**scene.meta, "lod": (c.num_drawn, scene.num_splats)}
    return Scene(
        out["means"],
        out["scales"],
        out["quats"],
        out["opacities"],
        out["sh"],
        out.get("filter_3d"),
        source=scene.source,
        meta=meta,
    )
