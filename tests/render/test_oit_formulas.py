"""The order-independent modes on hand-computed images (see test_oit.py): flat splats that cover the image with a
constant alpha, so each pixel is the formula evaluated once; wsr's int64 fixed point at huge view weights; one
splat per cell, where duplex is alpha blending of alpha/E in cell order (3DGS's C with E = 1, w_bg = 1)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_view
from reference import reference_render_oit
from test_oit import BACKGROUND, check, oit

import gbviewer as gb
from gbviewer.model.cells import Cells
from gbviewer.model.scene import SH_C0


def flat_cells(layers, E=4.0, wbg=0.25, W=16, H=12):
    """Splats facing a camera at the origin, 10^4 px wide (constant alpha over the image), grouped into cells.

    layers: list of (cell, depth, opacity, colour). Cells are spheres at their splats' mean depth."""
    f = 20.0
    n = len(layers)
    cell_of = np.array([c for c, _, _, _ in layers])
    Z = np.array([z for _, z, _, _ in layers], float)
    means = np.stack([np.zeros(n), np.zeros(n), Z], -1)
    scales = np.stack([1e4 * Z / f, 1e4 * Z / f, np.zeros(n)], -1)
    colours = np.array([c for _, _, _, c in layers], float)
    sh = ((colours - 0.5) / SH_C0)[:, None, :]
    m = cell_of.max() + 1
    cz = np.array([Z[cell_of == c].mean() for c in range(m)])
    cells = Cells.from_groups(
        np.stack([np.zeros(m), np.zeros(m), cz], -1), np.full((m, 3), 1e3), np.tile([1.0, 0, 0, 0], (m, 1)), cell_of
    )
    scene = gb.Scene.from_arrays(
        means,
        scales,
        np.tile([1.0, 0, 0, 0], (n, 1)),
        [o for _, _, o, _ in layers],
        sh,
        cells=cells,
        et_grade=E,
        weight_background=wbg,
    )
    return scene, gb.Camera(W, H, f, f, W / 2, H / 2, np.eye(3), np.zeros(3))


def test_duplex_hand_computed():
    """Two cells of two splats; cell 1 is listed first but lies behind cell 0."""
    c = [(1.0, 0.2, 0.1), (0.1, 0.9, 0.3), (0.2, 0.3, 1.0), (0.9, 0.9, 0.2)]
    layers = [(1, 6.0, 0.7, c[0]), (0, 3.0, 0.5, c[1]), (1, 5.0, 0.4, c[2]), (0, 2.0, 0.8, c[3])]
    E, wbg, bg = 4.0, 0.25, np.array(BACKGROUND)
    scene, cam = flat_cells(layers, E, wbg)
    frame = gb.render(scene, cam, "duplex", background=BACKGROUND)
    # cell 0 (depth 2.5) first: its splats both weigh alpha/E * 1; then cell 1 with T after cell 0
    a = {i: o / E for i, (_, _, o, _) in enumerate(layers)}
    T0 = (1 - a[1]) * (1 - a[3])
    w = {1: a[1], 3: a[3], 0: a[0] * T0, 2: a[2] * T0}
    T = T0 * (1 - a[0]) * (1 - a[2])
    S = sum(w.values()) + wbg * T
    expect = (sum(w[i] * np.array(c[i]) for i in w) + bg * wbg) / S
    assert np.abs(frame.rgb - expect).max() < 1e-5
    assert np.abs(frame.alpha - (1 - wbg / S)).max() < 1e-5


def test_duplex_cell_termination_hand_computed():
    """E = 1: two 0.99 splats in the front cell weigh 0.99 each (same T_cell), T = 1e-4 < 0.01 stops the pixel at the
    next cell and drops the background: the pixel is the plain average of the front cell's colours."""
    c = [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)]
    scene, cam = flat_cells([(0, 2.0, 0.99, c[0]), (0, 2.5, 0.99, c[1]), (1, 4.0, 0.9, c[2])], E=1.0, wbg=0.5)
    frame = gb.render(scene, cam, "duplex", background=BACKGROUND)
    assert np.abs(frame.rgb - np.array([0.5, 0.0, 0.5])).max() < 1e-5
    assert np.abs(frame.alpha - 1.0).max() < 1e-6
    # one splat per cell: the second cell enters at T = 0.02 and adds with weight 0.99 * 0.02; T = 2e-4 then stops
    # the pixel at the third cell and drops the background
    scene2, _ = flat_cells([(0, 2.0, 0.98, c[0]), (1, 2.5, 0.99, c[1]), (2, 4.0, 0.9, c[2])], E=1.0, wbg=0.5)
    f2 = gb.render(scene2, cam, "duplex", background=BACKGROUND)
    w = [0.98, 0.99 * 0.02]
    expect = (w[0] * np.array(c[0]) + w[1] * np.array(c[1])) / sum(w)
    assert np.abs(f2.rgb - expect).max() < 1e-5


def test_wsr_hand_computed():
    c = [(1.0, 0.2, 0.1), (0.1, 0.9, 0.3), (0.2, 0.3, 1.0)]
    scene, cam = flat_cells([(0, 2.0, 0.6, c[0]), (1, 3.0, 0.5, c[1]), (2, 4.0, 0.3, c[2])])
    scene = gb.Scene.from_arrays(
        scene.means,
        scene.scales,
        scene.quats,
        scene.opacities,
        scene.sh,
        view_weight_sh=np.array([[2.0], [1.0], [0.5]]) / SH_C0,
        weight_background=0.2,
    )
    frame = gb.render(scene, cam, "wsr", background=BACKGROUND)
    w = np.array([0.6 * 2.0, 0.5 * 1.0, 0.3 * 0.5])  # opacity * v; no clamp, no transmittance
    expect = ((w[:, None] * np.array(c)).sum(0) + 0.2 * np.array(BACKGROUND)) / (w.sum() + 0.2)
    assert np.abs(frame.rgb - expect).max() < 1e-5


def test_wsr_huge_view_weights_stay_in_int64():
    """Trained view weights of 10^9 make every alpha ~10^8: each is capped at WSR_FIXED_MAX = 64 before it weighs
    its colour, so three layers sum to 3 * 2^42 on the 2^-36 fixed-point grid. The former cap (2^26, i.e. 2^62 on
    the grid) overflowed int64 with two such terms and gave a negative weight sum."""
    c = [(1.0, 0.2, 0.1), (0.1, 0.9, 0.3), (0.2, 0.3, 1.0)]
    scene, cam = flat_cells([(0, 2.0, 0.6, c[0]), (1, 3.0, 0.5, c[1]), (2, 4.0, 0.3, c[2])])
    scene = gb.Scene.from_arrays(
        scene.means,
        scene.scales,
        scene.quats,
        scene.opacities,
        scene.sh,
        view_weight_sh=np.full((3, 1), 1e9 / SH_C0),
        weight_background=0.2,
    )
    frame = gb.render(scene, cam, "wsr", background=BACKGROUND)
    w = np.full(3, 64.0)  # every splat at the cap: equal weights, each keeps its colour
    expect = ((w[:, None] * np.array(c)).sum(0) + 0.2 * np.array(BACKGROUND)) / (w.sum() + 0.2)
    assert np.abs(frame.rgb - expect).max() < 1e-5
    assert np.abs(frame.alpha - (1 - 0.2 / (w.sum() + 0.2))).max() < 1e-6
    # a random scene: still finite, bounded and the float64 reference's (which caps the same way)
    scene, cam = random_view(34, n=120, sh_degree=3)
    vw = np.zeros((scene.num_splats, 16))
    vw[:, 0] = np.random.default_rng(34).uniform(1e6, 1e9, scene.num_splats)
    scene = gb.Scene.from_arrays(
        scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, view_weight_sh=vw, weight_background=0.3
    )
    frame = gb.render(scene, cam, "wsr", background=BACKGROUND)
    check(frame, reference_render_oit(scene, cam, "wsr", oit("wsr", wbg=0.3), None, 1, BACKGROUND))


def one_per_cell_formula(pre_alpha, colours, E, wbg, bg):
    """The derived one-splat-per-cell formula: with alphas a_k (sorted by depth, after the 0.99 clamp),
    T_k = prod_{j<k} (1 - a_j/E); splat k adds w_k = (a_k/E) T_k unless T_k < 0.01 (the pixel stops there);
    out = (sum_k w_k c_k + bg w_bg') / (sum_k w_k + w_bg' T_end), w_bg' = w_bg if T_end >= 0.01 else 0."""
    T, S, C = 1.0, 0.0, np.zeros(3)
    for a, c in zip(pre_alpha, colours):
        if T < 0.01:
            break
        w = a / E * T
        C, S, T = C + w * np.asarray(c), S + w, T * (1 - a / E)
    wb = wbg if T >= 0.01 else 0.0
    return (C + bg * wb) / (S + wb * T)


@pytest.mark.parametrize("E, wbg", [(4.0, 0.25), (1.0, 1.0), (2.0, 0.1)])
def test_one_splat_per_cell_formula(E, wbg):
    """Flat layers, each its own cell, listed in scrambled order."""
    rng = np.random.default_rng(int(E * 10))
    n = 7
    depth = rng.permutation(np.linspace(2.0, 8.0, n))
    op = rng.uniform(0.1, 0.99, n)
    col = rng.uniform(0, 1, (n, 3))
    scene, cam = flat_cells([(i, depth[i], op[i], col[i]) for i in range(n)], E, wbg)
    frame = gb.render(scene, cam, "duplex", background=BACKGROUND)
    order = np.argsort(depth)
    expect = one_per_cell_formula(op[order], col[order], E, wbg, np.array(BACKGROUND))
    assert np.abs(frame.rgb - expect).max() < 1e-5


def test_one_splat_per_cell_is_3dgs_when_E_1():
    """E = 1, w_bg = 1, black background, singleton cells: sum_k w_k + T_end = 1 (telescoping), so duplex = 3DGS's
    C wherever the transmittance stays above 0.01 (faint splats keep it there; opacity < 0.3 also keeps every alpha
    beyond the 3-sigma radius below 1/255, where duplex's radius test and scalar's plain alpha test agree)."""
    scene, cam = random_view(61, n=150, sh_degree=3)
    op = np.minimum(scene.opacities, 0.05)
    # each cell is its splat's ellipsoid at twice the scale: the cell's 2-sigma radius covers the splat's 3 sigma
    one = Cells.from_groups(scene.means, 2 * scene.scales, scene.quats, np.arange(scene.num_splats))
    sc = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, op, scene.sh, cells=one, weight_background=1.0)
    scalar = gb.render(sc, cam, "scalar")
    duplex = gb.render(sc, cam, "duplex", et_grade=1.0)
    assert (scalar.alpha < 0.99).all()
    assert np.abs(duplex.rgb - scalar.rgb).max() < 2e-5
