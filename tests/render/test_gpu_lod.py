"""The GPU backends draw a level-of-detail cut in place (glsl: gbviewer/render/glsl/lod.py, shaders/lod_rows.glsl;
cuda: native/cuda's stage and finish kernels): bit for bit the frames of the cut's gathered Scene in every mode
(duplex and stochastic_popfree render that Scene itself), the hierarchy uploaded once per scene and the cut's rows
only when they change. cuda skips without a GPU (bench/gpu_session.py runs it)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LOD_CAM as CAM
from helpers import filtered_scene, skip_or_fail

import gbviewer as gb
from gbviewer import lod
from gbviewer.render import BACKENDS, RenderSettings, create_renderer

# copies of a hierarchy (glsl: node geometry and SH; cuda: one call) and of a scene (glsl: geometry and SH)
TREE_UPLOADS = {"glsl": 2, "cuda": 1}
SCENE_UPLOADS = {"glsl": 2, "cuda": 1}

# every mode; eval3d and stopthepop on cuda only: their per-pixel orders (the exact one; StopThePop's 4x4 and 2x2
# stages) of these tile lists need more loop iterations than llvmpipe allows (glsl/limits.py)
SPECS = [
    "scalar",
    "gaussian_blending",
    "mip",
    "analytic",
    "scalar:2",
    "preset:spark",
    "wsr",
    "duplex",
    "stochastic",
    "stochastic_popfree",
]


@pytest.fixture(params=["glsl", "cuda"])
def backend(request) -> str:
    ok, why = BACKENDS[request.param].available()
    if not ok:
        if request.param == "cuda":
            pytest.skip(f"no CUDA device here: {why}")
        skip_or_fail(why)
    return request.param


def rendered(backend: str, scene: gb.Scene, cam: gb.Camera, spec: str) -> gb.Frame:
    r = create_renderer(backend)
    r.upload(scene)
    try:
        return r.render(cam, RenderSettings.parse(spec))
    finally:
        r.release()


@pytest.mark.parametrize("sh_dtype", ["float32", "float16"])
@pytest.mark.parametrize("rate", [1.0, 0.25])
def test_in_place_cut_equals_the_gathered_cut(backend, rate, sh_dtype):
    scene = filtered_scene(21, sh_dtype)
    view = CAM.at_sampling_rate(rate)
    renderer = create_renderer(backend)
    renderer.upload(scene)
    drawn = set()
    for tau in (0.0, 1.0, 3.0):
        gathered = lod.cut_scene(scene, view, tau)
        for spec in SPECS + (["eval3d", "stopthepop"] if backend == "cuda" else []):
            frame = renderer.render(view, RenderSettings.parse(f"{spec}+lod:{tau:g}"))
            ref = rendered(backend, gathered, view, spec)
            for a, b in ((frame.rgb, ref.rgb), (frame.alpha, ref.alpha), (frame.debug["evals"], ref.debug["evals"])):
                assert np.array_equal(a, b), (spec, tau)
            assert frame.stats.lod_splats == gathered.meta.get("lod", (scene.num_splats,))[0]
        drawn.add(frame.stats.lod_splats)
    assert len(drawn) == 3  # the taus draw different cuts: the comparison is not of one scene thrice


def test_the_hierarchy_goes_up_once_and_a_cut_when_it_changes(backend):
    scene = filtered_scene(22)
    r = create_renderer(backend)
    r.upload(scene)
    near, far = CAM, CAM.at_sampling_rate(0.25)
    gb_lod = RenderSettings.parse("gaussian_blending+lod:2")
    counts = []
    for cam, settings in (
        (near, gb_lod),
        (near, RenderSettings.parse("mip+lod:2")),
        (far, gb_lod),
        (far, RenderSettings.parse("gaussian_blending")),
        (far, gb_lod),
    ):
        before = r.uploads
        frame = r.render(cam, settings)
        counts.append((r.uploads - before, frame.stats.stage_reused))
    # the hierarchy's node geometry and SH with the first cut; a still camera's other pane: nothing;
    # another camera's cut: its rows alone; a frame without level of detail draws the scene's rows, then back
    tree = TREE_UPLOADS[backend]
    assert counts == [(tree + 1, False), (0, True), (1, False), (0, False), (0, False)], counts
    plain = rendered(backend, scene, far, "gaussian_blending")
    assert np.array_equal(r.render(far, RenderSettings.parse("gaussian_blending")).rgb, plain.rgb)
    before = r.uploads
    r.upload(scene)  # the scene again (geometry, SH): its hierarchy and cut again
    r.render(far, gb_lod)
    assert r.uploads - before == SCENE_UPLOADS[backend] + tree + 1
    r.release()
