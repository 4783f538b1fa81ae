"""The order-independent modes: wsr (LC-WSR) and duplex (Duplex-GS), on the CPU backend.

- Against the float64 reference (tests/reference.py: render_oit): every pixel within TOL = 1e-4 except threshold-tie
  pixels (an alpha within 3e-5 of 1/255, a pixel on a splat's radius circle, a transmittance within 2e-3 of the 0.01
  cell stop), which are counted and bounded as in test_render_reference.py.
- wsr is bitwise invariant to any permutation of the splats (the CPU sums in 64-bit fixed point), duplex to any
  permutation of the splats inside their cells (canonical member order).
- Hand-computed images: flat splats that cover the image with a constant alpha (sigma 10^4 px: alpha is within 1e-7
  of the opacity), so each pixel is the formula evaluated once.
- One splat per cell: duplex reduces to alpha blending of alpha/E in cell (= splat) depth order, normalised by the
  total weight with the background (see test_one_splat_per_cell_formula); with E = 1, w_bg = 1 and a black
  background that is exactly 3DGS's C.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import random_view
from reference import reference_render_oit

import gbviewer as gb
from gbviewer.cells import Cells, build_cells, cells_for
from gbviewer.errors import GBViewerError, SceneFormatError
from gbviewer.io import load, write_inria_ply
from gbviewer.scene import SH_C0, OitData

TOL = 1e-4
MAX_TIE_PIXELS = 12  # of 1920 output pixels
TIE_MAX_ERR = 3e-2
BACKGROUND = (0.1, 0.5, 0.9)


def oit(mode: str, et: float = 4.0, wbg: float | None = None, sigma: float = 10.0, depth_correct: bool = False):
    """The globals the renderer documents for scenes without trained ones: w_bg = 1 (wsr), 1/E (duplex)."""
    if wbg is None:
        wbg = 1.0 / et if mode == "duplex" else 1.0
    return {"sigma": sigma, "weight_background": wbg, "et_grade": et, "depth_correct": depth_correct}


def oit_of(scene: gb.Scene) -> OitData:
    """The scene's wsr / duplex data (all None for an ordinary scene)."""
    return scene.oit or OitData()


def with_view_weights(scene: gb.Scene, seed: int, sigma: float | None = None) -> gb.Scene:
    """The scene plus a random sort-free view weight (some splats get v <= 0 from some directions)."""
    rng = np.random.default_rng(seed)
    vw = rng.normal(0.0, 0.4, (scene.num_splats, 16))
    vw[:, 0] = rng.uniform(-0.5, 4.0, scene.num_splats)
    return gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d,
                                view_weight_sh=vw, wsr_sigma=sigma, weight_background=0.3)


def check(frame, ref):
    rgb, alpha, ties = ref
    assert np.isfinite(frame.rgb).all() and np.isfinite(frame.alpha).all()
    err = np.maximum(np.abs(frame.rgb - rgb).max(-1), np.abs(frame.alpha - alpha))
    strict = np.where(ties, 0.0, err)
    assert strict.max() <= TOL, f"max err {strict.max():.3e} off ties; {(strict > TOL).sum()} pixels above {TOL}"
    assert ties.sum() <= MAX_TIE_PIXELS, f"{ties.sum()} tie pixels"
    assert err.max() <= TIE_MAX_ERR
    return err


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed, weights, depth_correct", [(31, False, False), (32, True, False), (33, True, True)])
def test_wsr_matches_reference(seed, weights, depth_correct, supersample):
    scene, cam = random_view(seed, n=120, sh_degree=3)
    if weights:
        scene = with_view_weights(scene, seed, sigma=4.0)
    frame = gb.render(scene, cam, "wsr", supersample, background=BACKGROUND, depth_correct=depth_correct)
    params = oit("wsr", wbg=oit_of(scene).weight_background, sigma=oit_of(scene).sigma or 10.0, depth_correct=depth_correct)
    check(frame, reference_render_oit(scene, cam, "wsr", params, None, supersample, BACKGROUND))
    assert frame.stats.sort_length == 0 and frame.stats.pairs > 0


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed, k, et, weights", [(41, 5, 4.0, False), (42, 3, 1.0, True), (43, 8, 2.5, False)])
def test_duplex_matches_reference(seed, k, et, weights, supersample):
    scene, cam = random_view(seed, n=140, sh_degree=3)
    if weights:
        scene = with_view_weights(scene, seed)
    frame = gb.render(scene, cam, "duplex", supersample, background=BACKGROUND, et_grade=et, cell_size=k)
    params = oit("duplex", et, wbg=oit_of(scene).weight_background)
    ref = reference_render_oit(scene, cam, "duplex", params, cells_for(scene, k), supersample, BACKGROUND)
    check(frame, ref)
    st = frame.stats
    assert st.cells == -(-scene.num_splats // k) and 0 < st.cells_visible <= st.cells
    assert st.sort_length > 0 and st.pairs >= st.sort_length


def permuted(scene: gb.Scene, perm: np.ndarray, cells: Cells | None = None) -> gb.Scene:
    """The same splats listed in another order (cells renumbered to follow their splats)."""
    vw = oit_of(scene).view_weight_sh
    vw = None if vw is None else vw[perm]
    new_cells = None
    if cells is not None:
        inv = np.empty_like(perm)
        inv[perm] = np.arange(len(perm))
        new_cells = Cells.from_groups(cells.means, cells.scales, cells.quats, cells.cell_of(len(perm))[perm])
    return gb.Scene.from_arrays(scene.means[perm], scene.scales[perm], scene.quats[perm], scene.opacities[perm],
                                scene.sh[perm], view_weight_sh=vw, weight_background=oit_of(scene).weight_background,
                                cells=new_cells)


@pytest.mark.parametrize("supersample", [1, 2])
def test_wsr_bitwise_invariant_to_splat_order(supersample):
    scene, cam = random_view(51, n=400, sh_degree=3)
    scene = with_view_weights(scene, 51)
    a = gb.render(scene, cam, "wsr", supersample, background=BACKGROUND)
    for seed in (1, 2, 3):
        perm = np.random.default_rng(seed).permutation(scene.num_splats)
        b = gb.render(permuted(scene, perm), cam, "wsr", supersample, background=BACKGROUND)
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha), f"permutation {seed} changed bits"
        assert np.array_equal(a.debug["evals"], b.debug["evals"])


def test_duplex_bitwise_invariant_to_order_inside_cells():
    scene, cam = random_view(52, n=300, sh_degree=3)
    cells = build_cells(scene, 6)
    scene = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=cells)
    a = gb.render(scene, cam, "duplex", background=BACKGROUND)
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        # shuffle the members of every cell among their own positions, and the cells' splats across the scene
        perm = np.arange(scene.num_splats)
        for c in range(cells.num_cells):
            mem = cells.members[cells.offsets[c]:cells.offsets[c + 1]]
            perm[mem] = rng.permutation(mem)
        b = gb.render(permuted(scene, perm, cells), cam, "duplex", background=BACKGROUND)
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)


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
    cells = Cells.from_groups(np.stack([np.zeros(m), np.zeros(m), cz], -1), np.full((m, 3), 1e3),
                              np.tile([1.0, 0, 0, 0], (m, 1)), cell_of)
    scene = gb.Scene.from_arrays(means, scales, np.tile([1.0, 0, 0, 0], (n, 1)), [o for _, _, o, _ in layers], sh,
                                 cells=cells, et_grade=E, weight_background=wbg)
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
    scene = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh,
                                 view_weight_sh=np.array([[2.0], [1.0], [0.5]]) / SH_C0,
                                 weight_background=0.2)
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
    scene = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh,
                                 view_weight_sh=np.full((3, 1), 1e9 / SH_C0), weight_background=0.2)
    frame = gb.render(scene, cam, "wsr", background=BACKGROUND)
    w = np.full(3, 64.0)  # every splat at the cap: equal weights, each keeps its colour
    expect = ((w[:, None] * np.array(c)).sum(0) + 0.2 * np.array(BACKGROUND)) / (w.sum() + 0.2)
    assert np.abs(frame.rgb - expect).max() < 1e-5
    assert np.abs(frame.alpha - (1 - 0.2 / (w.sum() + 0.2))).max() < 1e-6
    # a random scene: still finite, bounded and the float64 reference's (which caps the same way)
    scene, cam = random_view(34, n=120, sh_degree=3)
    vw = np.zeros((scene.num_splats, 16))
    vw[:, 0] = np.random.default_rng(34).uniform(1e6, 1e9, scene.num_splats)
    scene = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh,
                                 view_weight_sh=vw, weight_background=0.3)
    frame = gb.render(scene, cam, "wsr", background=BACKGROUND)
    check(frame, reference_render_oit(scene, cam, "wsr", oit("wsr", wbg=0.3), None, 1, BACKGROUND))


def test_cells_must_partition_the_splats():
    """Cells are checked where they are made (shapes, offsets, negative members) and against the scene where every
    backend takes them (cells_for: members in range, each splat in at most one cell); the CPU module keeps its own
    check behind that."""
    scene, cam = random_view(94, n=12, sh_degree=0)
    g = build_cells(scene, 4)
    geom = (g.means, g.scales, g.quats)
    for offsets, members, what in [([1, 4, 8, 12], g.members, "offsets"), ([0, 8, 4, 12], g.members, "offsets"),
                                   ([0, 4, 8, 11], g.members, "offsets"), ([0, 4, 8], g.members, "offsets"),
                                   (g.offsets, np.r_[g.members[:-1], -1], "members"),
                                   (g.offsets, g.members.astype(np.float32), "members")]:
        with pytest.raises(GBViewerError, match=what):
            Cells(*geom, np.asarray(offsets), np.asarray(members))
    with pytest.raises(GBViewerError, match="quats"):
        Cells(g.means, g.scales, g.quats[:2], g.offsets, g.members)
    with pytest.raises(GBViewerError, match="outside the scene"):
        g.validate(11)
    repeated = Cells(*geom, g.offsets, np.r_[g.members[:-1], g.members[0]])
    sc = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=repeated)
    with pytest.raises(GBViewerError, match="more than once"):
        cells_for(sc)
    with pytest.raises(GBViewerError, match="more than once"):
        gb.render(sc, cam, "duplex")
    assert cells_for(gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh,
                                          cells=g)) is g

    # the native module on its own: the same partition check, and every result key the renderers read
    from gbviewer import _native
    from gbviewer.render.prepare import camera_args

    def native(members):
        r = _native.Renderer()
        r.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, None)
        r.upload_cells(g.means, g.scales, g.quats, g.offsets, np.ascontiguousarray(members, np.int32), g.cell_of(12))
        return r.render(*camera_args(cam), int(gb.Mode.DUPLEX), 1, 3, np.zeros(3, np.float32), False)

    with pytest.raises(ValueError, match="partition"):
        native(repeated.members)
    with pytest.raises(ValueError, match="partition"):
        native(np.r_[g.members[:-1], 12])
    out = native(g.members)
    assert {"rgb", "alpha", "evals", "preprocess_ms", "sort_ms", "blend_ms", "visible", "sort_length", "pairs",
            "cells_visible", "cell_misses", "evaluations"} <= set(out)
    assert 0 < out["cells_visible"] <= g.num_cells and out["evaluations"] == out["evals"].sum()


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
    sc = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, op, scene.sh, cells=one,
                              weight_background=1.0)
    scalar = gb.render(sc, cam, "scalar")
    duplex = gb.render(sc, cam, "duplex", et_grade=1.0)
    assert (scalar.alpha < 0.99).all()
    assert np.abs(duplex.rgb - scalar.rgb).max() < 2e-5


def test_cells_cover_members():
    """Built cells: all but one hold exactly K splats; each member's 3-sigma ellipsoid lies inside the cell's
    2-sigma ellipsoid (checked at its centre +- 3 sigma along its axes); few splat tiles fall outside cell rects."""
    scene, cam = random_view(71, n=500, sh_degree=0, kinds_p=[0.8, 0.2, 0, 0, 0, 0, 0])
    cells = build_cells(scene, 5)
    sizes = cells.sizes
    assert (sizes == 5).sum() >= cells.num_cells - 1 and sizes.sum() == scene.num_splats
    st = cells.stats()
    assert st["cells"] == 100 and st["members_max"] == 5 and "build_ms" in st
    from gbviewer.cells import rotation_matrices

    Rc = rotation_matrices(cells.quats)
    Rs = rotation_matrices(scene.quats)
    cell_of = np.repeat(np.arange(cells.num_cells), sizes)
    for i, c in zip(cells.members, cell_of):
        for ax in range(3):
            for sgn in (-1, 1):
                p = scene.means[i] + sgn * 3 * scene.scales[i, ax] * Rs[i][:, ax]
                local = Rc[c].T @ (p - cells.means[c]) / np.maximum(2 * cells.scales[c], 1e-12)
                assert local @ local <= 1 + 1e-4
    f = gb.render(scene, cam, "duplex")
    assert f.stats.cell_misses <= 0.01 * f.stats.pairs


def test_mode_labels_and_settings():
    scene, cam = random_view(81, n=30)
    s = gb.RenderSettings.parse("wsr")
    assert s.mode == gb.Mode.WSR and "approx" in s.label_for(scene)
    assert "approx" not in s.label_for(with_view_weights(scene, 1))
    assert "K=5" in gb.RenderSettings.parse("duplex").label_for(scene)
    assert [x.mode.label for x in gb.RenderSettings.parse_list("scalar,wsr,duplex:2")] == ["scalar", "wsr", "duplex"]
    with pytest.raises(gb.errors.RenderError):
        gb.RenderSettings("duplex", et_grade=0.0)
    f = gb.render(scene, cam, "duplex")
    assert "built cells" in f.stats.mode and f.stats.sort_bytes == 24 * f.stats.sort_length


def test_sort_free_ply_round_trip(tmp_path):
    scene, cam = random_view(91, n=60, sh_degree=3)
    scene = with_view_weights(scene, 91, sigma=7.5)
    path = tmp_path / "sortfree.ply"
    write_inria_ply(scene, path)
    loaded = load(path)
    assert loaded.meta["format"] == "sort-free-ply"
    np.testing.assert_array_equal(loaded.oit.view_weight_sh, scene.oit.view_weight_sh)
    assert loaded.oit.weight_background == pytest.approx(0.3) and loaded.oit.sigma == pytest.approx(7.5)
    a = gb.render(loaded, cam, "wsr", depth_correct=True)
    b = gb.render(scene, cam, "wsr", depth_correct=True)
    assert np.abs(a.rgb - b.rgb).max() < 1e-6  # the globals went through float32
    assert "approx" not in a.stats.mode


def test_sort_free_ply_errors(tmp_path):
    scene, _ = random_view(92, n=10, sh_degree=0)
    scene = with_view_weights(scene, 92, sigma=5.0)
    path = tmp_path / "s.ply"
    write_inria_ply(scene, path)
    text = path.read_bytes()
    bad = tmp_path / "noinfo.ply"
    bad.write_bytes(text.replace(b"property float info\n", b"property float infx\n"))
    with pytest.raises(SceneFormatError, match="info"):
        load(bad)
    bad2 = tmp_path / "ro.ply"
    bad2.write_bytes(text.replace(b"property float f_ro_14\n", b"property float g_ro_14\n"))
    with pytest.raises(SceneFormatError, match="f_ro"):
        load(bad2)


def test_cli_render_new_modes(tmp_path):
    from gbviewer.cli import main

    for mode in ("wsr", "duplex"):
        out = tmp_path / f"{mode}.npy"
        assert main(["render", str(gb.DEFAULT_SCENE), "--width", "48", "--height", "32", "--mode", mode,
                     "--out", str(out)]) == 0
        img = np.load(out)
        assert img.shape == (32, 48, 3) and np.isfinite(img).all() and img.max() > 0.05
    assert math.isfinite(float(img.mean()))


def test_cli_bench_order_independent(tmp_path):
    import json

    from gbviewer.cli import main

    out = tmp_path / "b.json"
    assert main(["bench", str(gb.DEFAULT_SCENE), "--modes", "wsr,duplex", "--views", "1", "--repeat", "1",
                 "--size", "48x32", "--rates", "1", "--flicker-frames", "3", "--json", str(out)]) == 0
    rows = {r["mode"]: r for r in json.loads(out.read_text())["order_independent"]}
    assert set(rows) == {"scalar", "wsr", "duplex"}
    assert rows["wsr"]["sort_length"] == 0 and rows["wsr"]["pairs"] == rows["scalar"]["pairs"] > 0
    assert 0 < rows["duplex"]["sort_length"] and rows["duplex"]["cells_visible"] <= rows["duplex"]["cells"]
    assert rows["scalar"]["psnr_vs_scalar"] == float("inf") and rows["duplex"]["psnr_vs_scalar"] > 10
    assert all(r["flicker"] >= 0 and set(r["stages_ms"]) >= {"preprocess_ms", "sort_ms", "blend_ms"} for r in rows.values())


def test_cells_follow_dropped_splats():
    """Scene.from_arrays drops non-finite splats; the members of given cells are renumbered with them."""
    scene, cam = random_view(93, n=40, sh_degree=0)
    cells = build_cells(scene, 4)
    means = scene.means.copy()
    means[5] = np.nan
    with pytest.warns(UserWarning, match="dropped 1"):
        sc = gb.Scene.from_arrays(means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=cells)
    assert sc.num_splats == 39 and sc.oit.cells.sizes.sum() == 39 and sc.oit.cells.num_cells == cells.num_cells
    assert sorted(sc.oit.cells.members) == list(range(39))
    assert np.isfinite(gb.render(sc, cam, "duplex").rgb).all()
