"""The order-independent modes: wsr (LC-WSR) and duplex (Duplex-GS), on the CPU backend.

- Against the float64 reference (tests/reference.py: render_oit): every pixel within TOL = 1e-4 except threshold-tie
  pixels (an alpha within 3e-5 of 1/255, a pixel on a splat's radius circle, a transmittance within 2e-3 of the 0.01
  cell stop), which are counted and bounded as in test_render_reference.py.
- wsr is bitwise invariant to any permutation of the splats (the CPU sums in 64-bit fixed point), duplex to any
  permutation of the splats inside their cells (canonical member order).
- Hand-computed images and the one-splat-per-cell formula: test_oit_formulas.py; cells, files and the command
  line: test_oit_cells.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_view
from reference import reference_render_oit

import gbviewer as gb
from gbviewer.model.cells import Cells, build_cells, cells_for
from gbviewer.model.scene import OitData

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
    return gb.Scene.from_arrays(
        scene.means,
        scene.scales,
        scene.quats,
        scene.opacities,
        scene.sh,
        scene.filter_3d,
        view_weight_sh=vw,
        wsr_sigma=sigma,
        weight_background=0.3,
    )


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
    params = oit(
        "wsr", wbg=oit_of(scene).weight_background, sigma=oit_of(scene).sigma or 10.0, depth_correct=depth_correct
    )
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
    return gb.Scene.from_arrays(
        scene.means[perm],
        scene.scales[perm],
        scene.quats[perm],
        scene.opacities[perm],
        scene.sh[perm],
        view_weight_sh=vw,
        weight_background=oit_of(scene).weight_background,
        cells=new_cells,
    )


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
            mem = cells.members[cells.offsets[c] : cells.offsets[c + 1]]
            perm[mem] = rng.permutation(mem)
        b = gb.render(permuted(scene, perm, cells), cam, "duplex", background=BACKGROUND)
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)
