"""The CPU renderer draws a level-of-detail cut in place (the stage reads the scene's and the hierarchy's rows; no
cut Scene is gathered or uploaded): bit-identical to rendering the gathered cut, stage kept per (camera, tau),
traces of its pixels, and the native hierarchy upload's checks."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LOD_CAM as CAM
from helpers import filtered_scene, front_camera, random_scene

import gbviewer as gb
from gbviewer import lod


@pytest.mark.parametrize("sh_dtype", ["float32", "float16"])
@pytest.mark.parametrize("rate", [1.0, 0.25, 0.125])
def test_in_place_cut_equals_the_gathered_cut(rate, sh_dtype):
    scene = filtered_scene(21, sh_dtype)
    view = CAM.at_sampling_rate(rate)
    renderer = gb.get_renderer(scene, "cpu")
    drawn = set()
    for tau in (0.0, 1.0, 3.0):
        gathered = lod.cut_scene(scene, view, tau)
        for spec in ("scalar", "gaussian_blending", "mip", "analytic", "scalar:2", "preset:spark", "wsr"):
            frame = renderer.render(view, gb.RenderSettings.parse(f"{spec}+lod:{tau:g}"))
            ref = gb.get_renderer(gathered, "cpu").render(view, gb.RenderSettings.parse(spec))
            for a, b in ((frame.rgb, ref.rgb), (frame.alpha, ref.alpha), (frame.debug["evals"], ref.debug["evals"])):
                assert np.array_equal(a, b), (spec, tau)
            assert frame.stats.lod_splats == gathered.meta.get("lod", (scene.num_splats,))[0]
        drawn.add(frame.stats.lod_splats)
    assert len(drawn) == 3  # the taus draw different cuts: the comparison is not of one scene thrice


def test_leaves_in_the_tree_order_are_read_row_by_row():
    """A cut's leaves come in the tree's (Morton) order unless they are over half the splats: in a scene laid out so
    that every level-1 node's children are rows 8q, 8q+2, 8q+1, 8q+3 ... 8q+7, each group of 8 leaves spans 8
    consecutive rows out of order, which the stage must not load as one run."""

    def rows(s: gb.Scene, index) -> gb.Scene:
        return gb.Scene(*(a[index] for a in (s.means, s.scales, s.quats, s.opacities, s.sh, s.filter_3d)))

    base = filtered_scene(26)
    n = base.num_splats - base.num_splats % 8
    base = rows(base, slice(0, n))
    swapped = np.arange(n)
    swapped[1::8], swapped[2::8] = swapped[2::8].copy(), swapped[1::8].copy()
    scene = rows(base, lod.build(base).order[swapped])  # the splat at Morton position p becomes row swapped[p]
    assert np.array_equal(lod.build(scene).order, swapped)
    renderer, view = gb.get_renderer(scene, "cpu"), CAM.at_sampling_rate(0.25)
    for tau, tree_order in ((2.0, True), (1.0, False)):
        c = lod.cut(lod.hierarchy_for(scene), view, tau)
        assert len(c.nodes)
        if tree_order:  # such groups are drawn
            assert len(c.leaves) <= n // 2 and (c.leaves[1::8] == c.leaves[::8] + 2).sum() > 10
        else:
            assert len(c.leaves) > n // 2 and (np.diff(c.leaves) > 0).all()
        gathered = gb.get_renderer(lod.cut_scene(scene, view, tau), "cpu")
        for mode in ("scalar", "gaussian_blending"):
            frame = renderer.render(view, gb.RenderSettings(mode, lod=tau))
            assert np.array_equal(frame.rgb, gathered.render(view, gb.RenderSettings(mode)).rgb), (mode, tau)


def test_the_stage_is_kept_per_camera_and_tau():
    scene = filtered_scene(22)
    renderer = gb.get_renderer(scene, "cpu")
    lod2, lod4, full = gb.RenderSettings(lod=2.0), gb.RenderSettings("gaussian_blending", lod=4.0), gb.RenderSettings()
    first = renderer.render_many([(CAM, lod2), (CAM, lod4), (CAM, full)])
    assert [f.stats.stage_reused for f in first] == [False, False, False]
    again = renderer.render_many([(CAM, gb.RenderSettings("gaussian_blending", lod=2.0)), (CAM, lod4), (CAM, full)])
    assert [f.stats.stage_reused for f in again] == [True, True, True]
    assert again[1].stats.lod_splats == first[1].stats.lod_splats < first[0].stats.lod_splats
    moved = gb.Camera(64, 48, 20.0, 20.0, 32, 24, np.eye(3), np.array([0.0, 0.0, -0.5]))
    assert not renderer.render(moved, lod2).stats.stage_reused
    other = filtered_scene(23)  # same sizes, another scene: never its stage
    renderer.upload(other)
    frame = renderer.render(CAM, lod2)
    assert not frame.stats.stage_reused
    assert np.array_equal(
        frame.rgb, gb.get_renderer(lod.cut_scene(other, CAM, 2.0), "cpu").render(CAM, gb.RenderSettings()).rgb
    )


def test_traces_of_an_in_place_cut_are_its_pixels():
    scene = filtered_scene(24)
    for mode in ("scalar", "gaussian_blending"):
        frame = gb.render(scene, CAM, mode, lod=2.0)
        for x, y in ((32, 24), (10, 40)):
            t = gb.trace_pixel(scene, CAM, x, y, mode, lod=2.0)
            np.testing.assert_allclose(t.color, frame.rgb[y, x], rtol=0, atol=1e-5)
            assert abs(t.transmittance - (1.0 - frame.alpha[y, x])) <= 1e-5
            assert t.mode == frame.stats.mode.split(",")[0]


def test_the_native_upload_checks_the_hierarchy():
    scene = filtered_scene(25)
    tree = lod.build(scene)
    native = gb.get_renderer(scene, "cpu")._impl
    sh = np.ascontiguousarray(tree.sh, np.float32)
    args = [tree.means, tree.scales, tree.quats, tree.opacities, sh, tree.filter_3d, tree.radius, tree.size]
    with pytest.raises(ValueError, match="upload_lod: levels"):
        native.upload_lod(*args, tree.levels[:-1].copy(), tree.order)
    bad = tree.order.copy()
    bad[5] = scene.num_splats
    with pytest.raises(ValueError, match="upload_lod: order"):
        native.upload_lod(*args, tree.levels, bad)
    with pytest.raises(ValueError, match="upload_lod: the interior arrays"):
        native.upload_lod(*args[:5], None, *args[6:], tree.levels, tree.order)
    with pytest.raises(ValueError, match="level of detail needs the scene's hierarchy"):
        native.render(
            np.eye(3, dtype=np.float32),
            np.zeros(3, np.float32),
            20.0,
            20.0,
            32.0,
            24.0,
            64,
            48,
            0.2,
            0,
            0,
            1,
            3,
            np.zeros(3, np.float32),
            False,
            lod=(1.0, 1.0, np.zeros(3, np.float32), 20.0, False),
        )


def test_a_coarse_cut_keeps_the_full_frames_buffers():
    """A preview's small cut of the uploaded scene does not free the frame buffers its next full frame needs again
    (a much smaller scene does: tests/render/test_render.py)."""
    from gbviewer.render.cpu import CpuRenderer

    scene = filtered_scene(26)
    r = CpuRenderer()
    r.upload(scene)
    full = r.render(CAM, gb.RenderSettings())
    kept = r._impl.buffer_bytes
    cut = r.render(CAM, gb.RenderSettings(lod=50.0))
    assert cut.stats.lod_splats * 4 < scene.num_splats  # a scene this small would release them
    assert r._impl.buffer_bytes >= kept
    assert np.array_equal(r.render(CAM, gb.RenderSettings()).rgb, full.rgb)


def test_cells_of_a_duplex_frame_do_not_stop_the_other_modes_cuts():
    """A duplex frame uploads the scene's cells; a later level-of-detail frame of another mode (a moving pane's
    preview) still draws its cut in place, and a duplex pane beside it draws the gathered cut."""
    scene = filtered_scene(27)
    renderer = gb.get_renderer(scene, "cpu")
    renderer.render(CAM, gb.RenderSettings("duplex"))
    for spec in ("scalar+lod:2", "gaussian_blending+lod:2", "duplex+lod:2"):
        frame = renderer.render(CAM, gb.RenderSettings.parse(spec))
        ref = gb.get_renderer(lod.cut_scene(scene, CAM, 2.0), "cpu").render(
            CAM, gb.RenderSettings.parse(spec.split("+")[0])
        )
        assert np.array_equal(frame.rgb, ref.rgb), spec
    both = renderer.render_many([(CAM, gb.RenderSettings("duplex")), (CAM, gb.RenderSettings(lod=2.0))])
    assert both[1].stats.lod_splats is not None


def test_a_cancelled_cut_stops_and_the_next_render_is_exact():
    """The cut reads the render's cancel flag: a set flag stops it (lod.cut, and so a gathered cut's prepare, raise
    RenderCancelled; a clear one changes nothing), and in-place LOD renders cancelled at any moment, the cut's
    included, end cancelled or exact, the next render exact."""
    import threading

    scene = filtered_scene(24)
    tree = lod.hierarchy_for(scene)
    token = gb.CancelToken()
    want = lod.cut(tree, CAM, 0.5)
    got = lod.cut(tree, CAM, 0.5, flag=token.flag)
    assert np.array_equal(got.leaves, want.leaves) and np.array_equal(got.node_weights, want.node_weights)
    token.set()
    with pytest.raises(gb.RenderCancelled):
        lod.cut(tree, CAM, 0.5, flag=token.flag)
    with pytest.raises(gb.RenderCancelled):
        lod.cut_scene(scene, CAM, 0.5, flag=token.flag)
    renderer = gb.get_renderer(scene, "cpu")
    settings = gb.RenderSettings("gaussian_blending", lod=0.5)
    ref = renderer.render(CAM, settings)
    other = gb.Camera(64, 48, 20.0, 20.0, 32, 24, np.eye(3), np.array([0.0, 0.0, -0.25]))
    for at_ms in (0.0, 0.2, 1.0, 3.0):
        renderer.render(other, settings)  # a stage of another camera: the next render cuts again
        token = gb.CancelToken()
        timer = threading.Timer(at_ms / 1e3, token.set)
        timer.start()
        try:
            assert np.array_equal(renderer.render(CAM, settings, cancel=token).rgb, ref.rgb)
        except gb.RenderCancelled:
            pass
        timer.join()
        assert np.array_equal(renderer.render(CAM, settings).rgb, ref.rgb)


def test_a_trace_names_the_scenes_splat_or_the_hierarchy_node_drawn_in_place():
    """With the cut drawn in place, a trace step's index is the scene's splat, or the interior node (flat id, `node`)
    drawn in its splats' place, as the gathered cut Scene's rows map to them; never the entry's position in the cut
    (which the inspector showed as "splat")."""
    scene = random_scene(3000, seed=6, spread=1.5)
    cam = front_camera(64, 48)
    tau = 8.0
    c = lod.cut(lod.hierarchy_for(scene), cam, tau)
    gathered = gb.trace_pixel(lod.cut_scene(scene, cam, tau), cam, 32, 24, "scalar")
    nl, n = len(c.leaves), scene.num_splats
    want = [
        (int(c.leaves[s.index]), False) if s.index < nl else (n + int(c.nodes[s.index - nl]), True)
        for s in gathered.steps
    ]
    traced = gb.trace_pixel(scene, cam, 32, 24, "scalar", lod=tau)
    assert [(s.index, s.node) for s in traced.steps] == want
    assert {s.node for s in traced.steps} == {False, True}  # both kinds at this pixel
    node = next(s for s in traced.steps if s.node)
    assert node.source == f"node {node.index}" and node.short == f"node {node.index}"
