"""Level of detail (gbviewer.lod): the merge rule, the moments of merged nodes against a float64 reference, the cut's
coverage for random cameras (inside the scene too), tau = 0 being the scene itself, cuts rendered in every mode. The
disk cache: test_lod_cache.py."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_scene, rotation

import gbviewer as gb
from gbviewer import lod
from gbviewer.core.errors import GBViewerError, RenderError
from gbviewer.lod.tree import BRANCHING


def rotations(quats: np.ndarray) -> np.ndarray:
    """(N,3,3) rotation matrices of unit quaternions (w,x,y,z), float64."""
    w, x, y, z = np.asarray(quats, np.float64).T
    return np.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        1,
    ).reshape(-1, 3, 3)


def covariances(scales: np.ndarray, quats: np.ndarray) -> np.ndarray:
    R = rotations(quats)
    return R @ (np.asarray(scales, np.float64)[:, :, None] ** 2 * R.transpose(0, 2, 1))


def areas(scales: np.ndarray) -> np.ndarray:
    """The rule's area of a Gaussian: the mean of its three principal cross-sections."""
    s = np.sort(np.asarray(scales, np.float64), axis=1)
    return np.pi / 3 * (s[:, 0] * s[:, 1] + s[:, 1] * s[:, 2] + s[:, 0] * s[:, 2])


def leaves_under(tree: lod.Hierarchy, node: int) -> np.ndarray:
    """Splat indices below interior node `node` (flat id): a contiguous run of the Morton order."""
    level = int(np.searchsorted(tree.levels, node, side="right")) - 1
    q = node - int(tree.levels[level])
    span = BRANCHING**level
    return tree.order[q * span : min((q + 1) * span, tree.num_leaves)]


def paired_scene(alpha: float) -> gb.Scene:
    """Two identical splats."""
    q = np.array([[0.9, 0.1, -0.3, 0.2]] * 2)
    return gb.Scene.from_arrays([[0.1, 0.2, 3.0]] * 2, [[0.3, 0.05, 0.1]] * 2, q, [alpha] * 2, np.full((2, 4, 3), 0.25))


@pytest.mark.parametrize("rule, expected", [("depth", lambda a: 1 - (1 - a) ** 2), ("sum", lambda a: min(1, 2 * a))])
@pytest.mark.parametrize("alpha", [0.2, 0.7])
def test_parent_of_identical_children_is_the_child(rule, expected, alpha):
    scene = paired_scene(alpha)
    tree = lod.build(scene, rule)
    assert tree.levels.tolist() == [0, 2, 3] and list(tree.children(2)) == [0, 1]
    np.testing.assert_allclose(tree.means[0], scene.means[0], atol=1e-7)
    np.testing.assert_allclose(
        covariances(tree.scales, tree.quats)[0], covariances(scene.scales, scene.quats)[0], atol=1e-7
    )
    np.testing.assert_allclose(tree.sh[0], scene.sh[0], atol=1e-7)
    np.testing.assert_allclose(tree.opacities[0], expected(alpha), rtol=1e-6)


def leaf_weights(scene: gb.Scene, rule: str = "depth") -> np.ndarray:
    """The rule's float64 merge weight of every splat: opacity x area ("depth"), or opacity alone ("opacity")."""
    return np.minimum(scene.opacities.astype(np.float64), 1 - 1e-7) * (areas(scene.scales) if rule == "depth" else 1)


def mixture_moments(scene: gb.Scene, idx: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, ...]:
    """The normalised weights, the mean, the offsets from it and the second central moment of the splats `idx`
    weighted by `w` (theirs), in float64."""
    ww = w / w.sum()
    mean = ww @ scene.means[idx].astype(np.float64)
    d = scene.means[idx] - mean
    cov = covariances(scene.scales[idx], scene.quats[idx])
    return ww, mean, d, np.einsum("i,ijk->jk", ww, cov + d[:, :, None] * d[:, None, :])


@pytest.mark.parametrize("seed, rule", [(0, "depth"), (1, "depth"), (2, "opacity")])
def test_merged_moments_are_the_weighted_moments_of_the_leaves(seed, rule):
    scene = random_scene(700, seed=seed, sh_degree=2)
    tree = lod.build(scene, rule)
    n = scene.num_splats
    w = leaf_weights(scene, rule)
    tau = -np.log1p(-np.minimum(scene.opacities.astype(np.float64), 1 - 1e-7)) * areas(scene.scales)
    for node in [n, n + 5, int(tree.levels[2]), int(tree.levels[-1]) - 1]:  # level 1, 2 and the root
        idx = leaves_under(tree, node)
        ww, mean, d, second = mixture_moments(scene, idx, w[idx])
        i = node - n
        np.testing.assert_allclose(tree.means[i], mean, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(
            covariances(tree.scales[i : i + 1], tree.quats[i : i + 1])[0],
            second,
            rtol=1e-5,
            atol=1e-6 * np.abs(second).max(),
        )
        np.testing.assert_allclose(
            tree.sh[i], np.einsum("i,ijk->jk", ww, scene.sh[idx].astype(np.float64)), rtol=1e-5, atol=1e-6
        )
        expect_alpha = -np.expm1(-tau[idx].sum() / areas(tree.scales[i : i + 1])[0])
        np.testing.assert_allclose(tree.opacities[i], expect_alpha, rtol=1e-5)
        d_max = np.linalg.norm(d, axis=1).max()
        assert tree.radius[i] >= d_max * (1 - 1e-6)


def morton_order(means: np.ndarray) -> np.ndarray:
    """The leaves' order by its definition: 21-bit Morton codes of the centres over their bounds, ties by index."""
    m = means.astype(np.float64)
    lo, hi = m.min(axis=0), m.max(axis=0)
    span = hi - lo
    u = np.where(span > 0, (m - lo) / np.where(span > 0, span, 1), 0.0)
    cell = np.minimum(u * 2097152.0, 2097151.0).astype(np.uint64)
    code = np.zeros(len(m), np.uint64)
    for bit in range(21):
        for axis in range(3):
            code |= ((cell[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.lexsort((np.arange(len(m)), code)).astype(np.int32)


@pytest.mark.parametrize("layout", ["spread", "one_cluster", "ties"])
def test_leaf_order_is_the_morton_order(layout):
    """The build's bucketed sort against the definition: spread centres, most of them in one bucket of the top
    bits (the bucket sorted by every thread), and exact ties (broken by index)."""
    rng = np.random.default_rng(11)
    n = 50_000
    means = rng.uniform(-1, 1, (n, 3))
    if layout == "one_cluster":
        means[: n - 10] = means[: n - 10] * 1e-4 + 0.3  # far splats stretch the bounds around a dense cluster
    if layout == "ties":
        means = np.round(means * 4) / 4  # 9^3 distinct centres
    scene = gb.Scene.from_arrays(
        means, np.full((n, 3), 0.01), np.tile([1.0, 0, 0, 0], (n, 1)), np.full(n, 0.5), np.zeros((n, 1, 3))
    )
    np.testing.assert_array_equal(lod.build(scene).order, morton_order(scene.means))


@pytest.mark.parametrize("case", ["spheres", "spheroids", "needles", "aligned_needles", "line", "plane"])
def test_merged_covariance_of_degenerate_and_extreme_children(case):
    """The eigen-decomposition behind a node's scales and rotation: repeated eigenvalues, a 1e4 scale ratio (a
    needle's thin axes to float precision, not to that of its long one), a rank-one or rank-two spread of the
    children's means."""
    rng = np.random.default_rng(7)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (8, 1)) if case == "spheres" else rng.normal(size=(8, 4))
    if case == "aligned_needles":
        q[:] = q[0]
    means = np.zeros((8, 3))
    scales = {
        "spheres": np.full((8, 3), 0.1),
        "spheroids": np.tile([0.2, 0.2, 0.05], (8, 1)),
        "needles": np.tile([1.0, 1e-4, 1e-4], (8, 1)),
        "aligned_needles": np.tile([1.0, 1e-4, 2e-4], (8, 1)),
    }.get(case, np.full((8, 3), 1e-3))
    if case == "line":
        means[:, 0] = np.linspace(-1, 1, 8)
    if case == "plane":
        means[:, :2] = rng.normal(size=(8, 2))
    scene = gb.Scene.from_arrays(means, scales, q, np.full(8, 0.5), np.full((8, 1, 3), 0.3))
    tree = lod.build(scene)
    assert tree.num_interior == 1
    got = covariances(tree.scales, tree.quats)[0]
    want = mixture_moments(scene, np.arange(8), leaf_weights(scene))[3]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    np.testing.assert_allclose(np.linalg.norm(tree.quats[0]), 1, atol=1e-6)
    if case == "aligned_needles":  # the node is the needle itself
        np.testing.assert_allclose(np.sort(tree.scales[0]), [1e-4, 2e-4, 1.0], rtol=1e-5)


def cameras(scene: gb.Scene, seed: int) -> list[gb.Camera]:
    """Random cameras around and inside the scene, perspective and orthographic."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds
    out = []
    for k in range(6):
        eye = rng.uniform(lo, hi) if k % 2 else (lo + hi) / 2 + rng.normal(size=3) * 6
        R = rotation(rng, np.pi)
        cam = gb.Camera(64, 48, 50.0, 55.0, 32, 24, R, -R @ eye)
        out.append(cam if k != 4 else cam.with_projection("orthographic", 4.0))
    return out


@pytest.mark.parametrize("band", [0.0, lod.DEFAULT_BAND])
def test_the_cut_covers_every_leaf_exactly_once(band):
    scene = random_scene(3000, seed=3)
    tree = lod.build(scene)
    n = scene.num_splats
    position = np.empty(n, np.int64)
    position[tree.order] = np.arange(n)
    for cam in cameras(scene, 5):
        for tau in (0.5, 2.0, 10.0):
            c = lod.cut(tree, cam, tau, band=band)
            assert len(np.unique(c.leaves)) == len(c.leaves) and len(np.unique(c.nodes)) == len(c.nodes)
            assert ((c.leaf_weights > 0) & (c.leaf_weights <= 1)).all()
            assert ((c.node_weights > 0) & (c.node_weights <= 1)).all()
            drawn = np.zeros(int(tree.levels[-1]))
            drawn[position[c.leaves]] = c.leaf_weights  # a leaf's flat id is its Morton position
            drawn[n + c.nodes] = c.node_weights
            coverage = np.zeros(n)  # per leaf: the drawn weights of its path to the root
            for level in range(len(tree.levels) - 1):
                ids = tree.levels[level] + np.arange(n) // BRANCHING**level
                coverage += drawn[ids]
            if band == 0:
                assert (coverage == 1).all(), (cam.name, tau)
                assert (c.leaf_weights == 1).all() and (c.node_weights == 1).all()
            else:
                np.testing.assert_allclose(coverage, 1, atol=1e-6)
        assert lod.cut(tree, cam, 50.0).num_drawn < n  # the cut does coarsen


def flat_weights(tree: lod.Hierarchy, c: lod.Cut) -> np.ndarray:
    """The drawn weight of every node by flat id (0: not drawn)."""
    n = tree.num_leaves
    position = np.empty(n, np.int64)
    position[tree.order] = np.arange(n)
    out = np.zeros(int(tree.levels[-1]))
    out[position[c.leaves]] = c.leaf_weights
    out[n + c.nodes] = c.node_weights
    return out


def test_cut_weights_are_continuous_in_tau():
    """With the fade band every node's weight moves by little between nearby tau (no popping); a hard cut jumps."""
    scene = random_scene(3000, seed=8)
    tree = lod.build(scene)
    cam = cameras(scene, 9)[0]
    taus = np.geomspace(0.5, 30.0, 300)  # steps of 1.4 %
    for band, bound in ((lod.DEFAULT_BAND, 0.1), (0.0, None)):
        w = np.stack([flat_weights(tree, lod.cut(tree, cam, t, band=band)) for t in taus])
        step = np.abs(np.diff(w, axis=0)).max()
        assert lod.cut(tree, cam, taus[0], band=band).num_drawn > lod.cut(tree, cam, taus[-1], band=band).num_drawn
        if bound is None:
            assert step == 1.0
        else:
            assert step < bound, step


def test_tau_zero_is_the_leaf_set_and_renders_bit_identically():
    scene = random_scene(500, seed=4, sh_degree=1)
    tree = lod.build(scene)
    cam = gb.Camera(64, 48, 60.0, 60.0, 32, 24, np.eye(3), np.zeros(3))
    c = lod.cut(tree, cam, 0.0)
    assert c.leaves.tolist() == list(range(scene.num_splats)) and (c.leaf_weights == 1).all() and not len(c.nodes)
    assert lod.cut_scene(scene, cam, 0.0) is scene
    for mode in ("scalar", "gaussian_blending"):
        full = gb.render(scene, cam, mode)
        zero = gb.render(scene, cam, mode, lod=0)
        assert np.array_equal(full.rgb, zero.rgb) and np.array_equal(full.alpha, zero.alpha)
        assert zero.stats.lod_splats == scene.num_splats and full.stats.lod_splats is None


def test_cut_scene_renders_in_every_mode_with_its_label():
    scene = random_scene(2000, seed=6, sh_degree=1, spread=3.0)
    cam = gb.Camera(64, 48, 20.0, 20.0, 32, 24, np.eye(3), np.zeros(3))
    cut = lod.cut_scene(scene, cam, 2.0)
    drawn, total = cut.meta["lod"]
    assert drawn == cut.num_splats and total == scene.num_splats and cut.sh.shape[1:] == scene.sh.shape[1:]
    for spec in (
        "scalar+lod:2",
        "mip+lod:2",
        "analytic+lod:2",
        "gaussian_blending+lod:2",
        "scalar:2+lod:2",
        "wsr+lod:2",
        "duplex+lod:2",
    ):
        settings = gb.RenderSettings.parse(spec)
        assert settings.lod == 2.0 and gb.RenderSettings.parse(settings.spec) == settings
        frame = gb.get_renderer(scene, "cpu").render(cam, settings)
        direct = gb.get_renderer(cut, "cpu").render(cam, gb.RenderSettings.parse(spec.split("+")[0]))
        assert np.array_equal(frame.rgb, direct.rgb), spec
        assert frame.stats.lod_splats == drawn
        assert frame.stats.mode.endswith(f"LOD \u03c4=2 px, {drawn:,} of {total:,} splats"), frame.stats.mode
    assert gb.RenderSettings(lod=2).label_for(scene) == "scalar LOD \u03c4=2 px"  # a whole scene: no cut's counts
    for bad in ("scalar+lod:x", "scalar+mip", "scalar+lod:-1"):
        with pytest.raises(RenderError):
            gb.RenderSettings.parse(bad)


def test_cut_refuses_scenes_with_order_independent_data():
    base = random_scene(50, seed=7)
    scene = gb.Scene.from_arrays(
        base.means, base.scales, base.quats, base.opacities, base.sh, view_weight_sh=np.ones((50, 1))
    )
    with pytest.raises(GBViewerError, match="level of detail is for plain splat scenes"):
        lod.cut_scene(scene, gb.Camera(8, 8, 8.0, 8.0, 4, 4, np.eye(3), np.zeros(3)), 1.0)


def test_render_many_mixing_lod_and_full_panes_matches_single_renders():
    """The viewer's companion panes: one camera, a full pane and LOD panes in one render_many (the cut is another
    view scene: its own batch), each bit-identical to its own render."""
    scene = random_scene(2000, seed=12, sh_degree=1, spread=3.0)
    cam = gb.Camera(64, 48, 20.0, 20.0, 32, 24, np.eye(3), np.zeros(3))
    settings = [
        gb.RenderSettings(),
        gb.RenderSettings(lod=2.0),
        gb.RenderSettings(),
        gb.RenderSettings("gaussian_blending", lod=4.0),
    ]
    renderer = gb.get_renderer(scene, "cpu")
    many = renderer.render_many([(cam, s) for s in settings])
    for s, frame in zip(settings, many):
        alone = gb.get_renderer(scene, "cpu").render(cam, s)
        assert np.array_equal(frame.rgb, alone.rgb) and frame.stats.lod_splats == alone.stats.lod_splats, s.spec
    assert not np.array_equal(many[0].rgb, many[1].rgb)
