"""The order-independent modes' cells and files (see test_oit.py): cells partition and cover their splats and follow
dropped ones, mode labels, sort-free .ply round trips and errors, the command line's render and bench."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import random_scene, random_view
from test_oit import with_view_weights

import gbviewer as gb
from gbviewer.core.errors import GBViewerError, SceneFormatError
from gbviewer.io import load, write_inria_ply
from gbviewer.model.cells import Cells, build_cells, cells_for


def test_cells_must_partition_the_splats():
    """Cells are checked where they are made (shapes, offsets, negative members) and against the scene where every
    backend takes them (cells_for: members in range, each splat in at most one cell); the CPU module keeps its own
    check behind that."""
    scene, cam = random_view(94, n=12, sh_degree=0)
    g = build_cells(scene, 4)
    geom = (g.means, g.scales, g.quats)
    for offsets, members, what in [
        ([1, 4, 8, 12], g.members, "offsets"),
        ([0, 8, 4, 12], g.members, "offsets"),
        ([0, 4, 8, 11], g.members, "offsets"),
        ([0, 4, 8], g.members, "offsets"),
        (g.offsets, np.r_[g.members[:-1], -1], "members"),
        (g.offsets, g.members.astype(np.float32), "members"),
    ]:
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
    assert (
        cells_for(gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, cells=g)) is g
    )

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
    assert {
        "rgb",
        "alpha",
        "evals",
        "preprocess_ms",
        "sort_ms",
        "blend_ms",
        "visible",
        "sort_length",
        "pairs",
        "cells_visible",
        "cell_misses",
        "evaluations",
    } <= set(out)
    assert 0 < out["cells_visible"] <= g.num_cells and out["evaluations"] == out["evals"].sum()


def test_cells_cover_members():
    """Built cells: all but one hold exactly K splats; each member's 3-sigma ellipsoid lies inside the cell's
    2-sigma ellipsoid (checked at its centre +- 3 sigma along its axes); few splat tiles fall outside cell rects."""
    scene, cam = random_view(71, n=500, sh_degree=0, kinds_p=[0.8, 0.2, 0, 0, 0, 0, 0])
    cells = build_cells(scene, 5)
    sizes = cells.sizes
    assert (sizes == 5).sum() >= cells.num_cells - 1 and sizes.sum() == scene.num_splats
    st = cells.stats()
    assert st["cells"] == 100 and st["members_max"] == 5 and "build_ms" in st
    from gbviewer.model.cells import rotation_matrices

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
    with pytest.raises(gb.RenderError):
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
        assert (
            main(
                ["render", str(gb.DEFAULT_SCENE), "--width", "48", "--height", "32", "--mode", mode, "--out", str(out)]
            )
            == 0
        )
        img = np.load(out)
        assert img.shape == (32, 48, 3) and np.isfinite(img).all() and img.max() > 0.05
    assert math.isfinite(float(img.mean()))


def test_cli_bench_order_independent(tmp_path):
    import json

    from gbviewer.cli import main

    out = tmp_path / "b.json"
    assert (
        main(
            [
                "bench",
                str(gb.DEFAULT_SCENE),
                "--modes",
                "wsr,duplex",
                "--views",
                "1",
                "--repeat",
                "1",
                "--size",
                "48x32",
                "--rates",
                "1",
                "--flicker-frames",
                "3",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    rows = {r["mode"]: r for r in json.loads(out.read_text())["order_independent"]}
    assert set(rows) == {"scalar", "wsr", "duplex"}
    assert rows["wsr"]["sort_length"] == 0 and rows["wsr"]["pairs"] == rows["scalar"]["pairs"] > 0
    assert 0 < rows["duplex"]["sort_length"] and rows["duplex"]["cells_visible"] <= rows["duplex"]["cells"]
    assert rows["scalar"]["psnr_vs_scalar"] is None  # infinite (identical images): strict JSON writes it as null
    assert rows["duplex"]["psnr_vs_scalar"] > 10
    assert all(
        r["flicker"] >= 0 and set(r["stages_ms"]) >= {"preprocess_ms", "sort_ms", "blend_ms"} for r in rows.values()
    )


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


def test_the_shared_cells_are_read_only():
    """cells_for hands every backend the scene's one Cells, whose members are checked once (validate) and then
    indexed unchecked: an edit after the check (cells.members[1] = cells.members[0]) went unseen."""
    from gbviewer.model.cells import cells_for

    scene = random_scene(400, seed=12)
    cells = cells_for(scene)
    for name in ("means", "scales", "quats", "offsets", "members"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(cells, name)[0] = 0
