"""The level-of-detail cut's top-down walk (native/cpu/lod_cut.cpp) against the cut by its definition over every node:
bit for bit on small and large trees and any thread count, and a stop anywhere in it cancelling the whole cut."""

from __future__ import annotations

import dataclasses

import numpy as np
from helpers import random_scene
from test_lod import cameras

import gbviewer as gb
from gbviewer import lod
from gbviewer.core.errors import RenderCancelled


def cut_over_every_node(tree: lod.Hierarchy, cam: gb.Camera, tau: float, band: float = lod.DEFAULT_BAND) -> lod.Cut:
    """The cut by its definition: the walk forced to evaluate every node (as it does once most of a large tree is
    reached)."""
    from gbviewer._native import testing

    try:
        testing.set_cut_flat_above(0)
        return lod.cut(tree, cam, tau, band)
    finally:
        testing.set_cut_flat_above(65536)


def assert_same_cut(got: lod.Cut, want: lod.Cut, where) -> None:
    """Indices and weights equal bit for bit, dtypes too."""
    for field in ("leaves", "leaf_weights", "nodes", "node_weights"):
        a, b = getattr(got, field), getattr(want, field)
        assert a.dtype == b.dtype and np.array_equal(a, b), (where, field)


def test_the_top_down_cut_equals_the_cut_over_every_node():
    """The cut walks only the nodes it reaches; forced to evaluate every node (as it does once most of a large tree
    is reached) it gives the same indices and weights, bit for bit."""
    scene = random_scene(5000, seed=13, spread=3.0)
    tree = lod.build(scene)
    for cam in cameras(scene, 5):
        for tau, band in ((0.0, 1.0), (0.5, 1.0), (2.0, 0.0), (10.0, 1.0), (200.0, 1.0)):
            assert_same_cut(lod.cut(tree, cam, tau, band), cut_over_every_node(tree, cam, tau, band), (cam.name, tau))


def test_the_top_down_cut_equals_the_cut_over_every_node_on_a_large_tree():
    """Large enough for the walk's levels to run on several threads (counted, then written at each thread's offsets),
    with coarse cuts (leaves in the tree's order) and a fine one (over half the splats: ascending)."""
    scene = random_scene(400_000, seed=21, spread=30.0)
    tree = lod.build(scene)
    n = scene.num_splats
    for dist, lo, hi in ((750.0, 16384, n // 16), (600.0, n // 16, n // 4), (300.0, n // 2 + 1, n)):
        cam = gb.Camera(640, 480, 500.0, 500.0, 320, 240, np.eye(3), np.array([0.0, 0.0, dist]))
        flat = cut_over_every_node(tree, cam, 2.0)
        for threads in (1, 2, 3):
            walked = lod.cut(tree, cam, 2.0, threads=threads)
            assert lo <= len(walked.leaves) < hi, (dist, len(walked.leaves))
            assert_same_cut(walked, flat, (dist, threads))


def test_a_cut_stopped_anywhere_is_cancelled_never_partial():
    """A stop at any of a cut's checks (between levels, inside a level's count or write, the fallback's check, the
    leaves' sort) raises RenderCancelled; a cut that was not stopped is the whole cut. Levels large enough for the
    fallback's check (lowered to 1000 nodes) and several threads."""
    from gbviewer._native import testing

    scene = random_scene(60_000, seed=22, spread=10.0)
    tree = lod.build(scene)
    cams = [gb.Camera(320, 240, 250.0, 250.0, 160, 120, np.eye(3), np.array([0.0, 0.0, d])) for d in (150.0, 300.0)]
    try:
        testing.set_cut_flat_above(1000)
        for cam in cams:
            full = lod.cut(tree, cam, 1.0, threads=3)
            stopped = 0
            for k in range(0, 90, 2):
                testing.set_cut_stop_after(k)
                try:
                    got = lod.cut(tree, cam, 1.0, threads=3)
                except RenderCancelled:
                    stopped += 1
                    continue
                finally:
                    testing.set_cut_stop_after(-1)
                assert_same_cut(got, full, k)
            assert 3 <= stopped < 45, stopped  # the stop did land inside these cuts, and some ran to the end
    finally:
        testing.set_cut_flat_above(65536)


def projected_sizes(tree: lod.Hierarchy, cam: gb.Camera) -> np.ndarray:
    """Every interior node's projected size p in pixels, in float64 as the definition states it (infinite where the
    eye is within the node's radius)."""
    f = float(max(cam.fx, cam.fy))
    if cam.orthographic:
        return tree.size.astype(np.float64) * f
    d = tree.means.astype(np.float64) - np.asarray(cam.position, np.float32).astype(np.float64)
    gap = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]) - tree.radius
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(gap > 0, tree.size.astype(np.float64) * f / gap, np.inf)


def cut_by_numpy(tree: lod.Hierarchy, cam: gb.Camera, tau: float, band: float) -> lod.Cut:
    """The cut's definition (gbviewer.lod.cut) computed independently in numpy: each interior node's o from its
    projected size in float64, rounded to float32 as the native cut keeps it; weights multiplied top-down in float32."""
    from gbviewer.lod.tree import BRANCHING

    n, lv = tree.num_leaves, tree.levels
    p = projected_sizes(tree, cam)
    with np.errstate(invalid="ignore"):
        if tau <= 0:
            o = np.ones_like(p)
        else:
            o = np.clip((p - tau) / (tau * band), 0.0, 1.0) if band > 0 else (p >= tau).astype(np.float64)
    o = o.astype(np.float32)
    w = np.zeros(len(o), np.float32)
    w[-1] = 1.0
    for level in range(len(lv) - 3, 0, -1):
        ids = np.arange(lv[level], lv[level + 1])
        parent = lv[level + 1] + (ids - lv[level]) // BRANCHING - n
        w[ids - n] = w[parent] * o[parent]
    parent = lv[1] + np.arange(n) // BRANCHING - n
    leaf_w = w[parent] * o[parent]  # by Morton position
    node_w = w * (np.float32(1.0) - o)
    drawn, nodes = np.flatnonzero(leaf_w > 0), np.flatnonzero(node_w > 0).astype(np.int32)
    if len(drawn) > n // 2:  # over half the splats: ascending, else in the tree's order
        drawn = drawn[np.argsort(tree.order[drawn])]
    return lod.Cut(tree.order[drawn], leaf_w[drawn], nodes, node_w[nodes])


def test_the_cut_equals_its_definition_computed_in_numpy_at_the_band_edges():
    """The native opening test decides most nodes without a square root or a division and defers to the exact form
    within a margin: every node's o must still be the definition's. tau is put a hair (1e-13 relative) on either
    side of nodes' exact projected sizes, and the band's upper edge likewise (band 1e-9 makes o there visible in
    float32), for cameras outside and inside the scene and an orthographic one."""
    scene = random_scene(20_000, seed=31, spread=6.0)
    tree = lod.build(scene)
    rng = np.random.default_rng(31)
    checked = 0
    for cam in cameras(scene, 8):
        p = projected_sizes(tree, cam)
        finite = np.flatnonzero(np.isfinite(p) & (p > 0))
        for k in rng.choice(finite, 4, replace=False):
            for nudge in (-1e-13, 0.0, 1e-13):
                for tau, band in (
                    (p[k] * (1 + nudge), 1.0),
                    (p[k] * (1 + nudge), 0.0),
                    (p[k] / (1 + 1e-9) * (1 + nudge), 1e-9),
                ):
                    want = cut_by_numpy(tree, cam, tau, band)
                    assert_same_cut(lod.cut(tree, cam, tau, band), want, (cam.name, k, nudge, band))
                    checked += 1
    assert checked == 6 * 4 * 3 * 3


def test_the_cut_equals_its_definition_on_a_hierarchy_with_negative_radii():
    """The squared tests hold only for radius >= 0 (s + radius tau can cancel below its rounding otherwise): a damaged
    hierarchy with negative radii, tau at nodes' exact projected sizes, still gets the definition's cut."""
    scene = random_scene(5000, seed=32, spread=4.0)
    tree = lod.build(scene)
    rng = np.random.default_rng(32)
    radius = tree.radius.copy()
    flip = rng.random(len(radius)) < 0.5
    radius[flip] = -radius[flip] * rng.uniform(0.5, 2.0, flip.sum()).astype(np.float32)
    damaged = dataclasses.replace(tree, radius=radius)
    # a root whose s + radius tau cancels to 0 exactly while the eye is 1e-30 from its centre: p = tau exactly, o = 1
    means, size = tree.means.copy(), tree.size.copy()
    means[-1], radius[-1], size[-1] = (1e-30, 0.0, 0.0), -1.0, 1.0 / 64.0
    root_case = dataclasses.replace(tree, means=means, radius=radius, size=size)
    at_origin = gb.Camera(64, 48, 64.0, 64.0, 32, 24, np.eye(3), np.zeros(3))
    for band in (0.0, 1.0):
        assert_same_cut(lod.cut(root_case, at_origin, 1.0, band), cut_by_numpy(root_case, at_origin, 1.0, band), band)
    for cam in cameras(scene, 9)[:4]:
        p = projected_sizes(damaged, cam)
        for k in rng.choice(np.flatnonzero(np.isfinite(p)), 5, replace=False):
            for band in (0.0, 1.0):
                want = cut_by_numpy(damaged, cam, p[k], band)
                assert_same_cut(lod.cut(damaged, cam, p[k], band), want, (k, band))
