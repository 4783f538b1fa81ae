"""The per-camera stage (gbv/preprocess_stage.h; the CPU's frame.cpp, the GLSL port's stage.comp, CUDA's
stage_kernel) and `render_many`: frames that reuse a stage, or share one inside a call, equal the same frames rendered
by fresh renderers bit for bit; the stage is rebuilt when the camera, the scene (another scene, or the same one
modified and uploaded again) or the SH degree changes, on every backend with `Capabilities.shared_stage` that runs
here; the CPU's render_many shares one stage per distinct camera, its partial frames end equal to its frames, and a
cancelled render_many raises and the next render is exact."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from helpers import SHARED_SCENES, shared_scene

import gbviewer as gb
from gbviewer.render import BACKENDS, RenderSettings, create_renderer
from gbviewer.render.view_filter import ViewFilter

SCENES = sorted(p.name for p in SHARED_SCENES.glob("*") if p.suffix != ".md") or ["biker.compressed.ply"]
SPECS = ["scalar", "gaussian_blending", "mip", "analytic", "scalar:2", "preset:supersplat", "wsr", "duplex"]
COUNTS = ("visible", "sort_length", "pairs", "evaluations")


@pytest.fixture(params=[name for name, cls in BACKENDS.items() if cls.capabilities.shared_stage])
def staged(request) -> str:
    """A backend with a shared per-camera stage that runs here."""
    ok, why = BACKENDS[request.param].available()
    if not ok:
        pytest.skip(f"{request.param} backend unavailable here: {why}")
    return request.param


def fresh(scene: gb.Scene, cam: gb.Camera, settings: RenderSettings, backend: str = "cpu") -> gb.Frame:
    r = create_renderer(backend)
    r.upload(scene)
    try:
        return r.render(cam, settings)
    finally:
        r.release()


def same(a: gb.Frame, b: gb.Frame, where: str) -> None:
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha), where
    assert np.array_equal(a.debug["evals"], b.debug["evals"]), where
    for key in COUNTS:
        assert getattr(a.stats, key) == getattr(b.stats, key), f"{where}: {key}"


@pytest.mark.parametrize("name", SCENES)
def test_render_many_equals_fresh_renders(name):
    scene = gb.load(shared_scene(name))
    cam = gb.orbit_camera(scene, 30, 20, width=160, height=120)
    jobs = [(cam, RenderSettings.parse(s)) for s in SPECS] + [(cam.at_sampling_rate(0.5), RenderSettings())]
    r = create_renderer("cpu")
    r.upload(scene)
    frames = r.render_many(jobs)
    reused = [f.stats.stage_reused for f in frames]
    # one stage per distinct camera: x1 (built by the first job), x1 at 2x2 samples, x1/2
    assert reused == [False, True, True, True, False, True, True, True, False], reused
    for (c, s), f in zip(jobs, frames):
        same(f, fresh(scene, c, s), f"{name} {s.spec} {c.width}x{c.height}")
    again = r.render(cam, RenderSettings.parse("gaussian_blending"))  # a later call reuses the last call's stage
    assert again.stats.stage_reused and again.stats.stage_ms == 0.0 == again.stats.order_ms
    assert frames[0].stats.order_ms > 0 and frames[0].stats.order_ms <= frames[0].stats.sort_ms
    same(again, frames[1], f"{name} gaussian_blending again")


def test_sequential_modes_reuse_the_stage_and_stay_exact(staged):
    scene = gb.load(shared_scene("plant.splat"))
    cam = gb.orbit_camera(scene, 50, 10, width=128, height=96)
    r = create_renderer(staged)
    r.upload(scene)
    for i, spec in enumerate(["mip", "scalar", "gaussian_blending", "preset:gsplat-antialiased", "analytic", "wsr"]):
        f = r.render(cam, RenderSettings.parse(spec))
        assert f.stats.stage_reused == (i > 0), spec
        assert (f.stats.stage_ms == 0.0) == (i > 0) and f.stats.stage_ms <= f.stats.preprocess_ms, spec
        same(f, fresh(scene, cam, RenderSettings.parse(spec), staged), spec)
    wide = RenderSettings(view_filter=ViewFilter(2.0))  # a wider 2D filter: another on-screen reach, another stage
    f = r.render(cam, wide)
    assert not f.stats.stage_reused
    same(f, fresh(scene, cam, wide, staged), "dilation 2")


def test_render_many_builds_one_stage_per_camera_and_keeps_the_jobs_order(staged):
    """Jobs of two cameras interleaved: each camera's stage is built once (the default render_many groups a camera's
    jobs), and the frames come back in the jobs' order, each as a fresh renderer draws it."""
    scene = gb.load(shared_scene("plant.splat"))
    a, b = (gb.orbit_camera(scene, az, 10, width=96, height=72) for az in (20, 60))
    jobs = [
        (a, RenderSettings.parse("scalar")),
        (b, RenderSettings.parse("scalar")),
        (a, RenderSettings.parse("gaussian_blending")),
        (b, RenderSettings.parse("mip")),
    ]
    r = create_renderer(staged)
    r.upload(scene)
    frames = r.render_many(jobs)
    assert [f.stats.stage_reused for f in frames] == [False, False, True, True]
    for (cam, settings), f in zip(jobs, frames):
        same(f, fresh(scene, cam, settings, staged), f"{staged} {settings.spec}")


def test_the_stage_is_rebuilt_when_camera_scene_or_sh_degree_change(staged):
    a = gb.load(shared_scene("fruit_drops_minimal.ply"))  # SH degree 3
    cam = gb.orbit_camera(a, 30, 20, width=96, height=72)
    r = create_renderer(staged)
    r.upload(a)
    s = RenderSettings()
    assert not r.render(cam, s).stats.stage_reused
    assert r.render(cam, s).stats.stage_reused
    moved = gb.orbit_camera(a, 31, 20, width=96, height=72)
    assert not r.render(moved, s).stats.stage_reused
    f = r.render(moved, RenderSettings(sh_degree=1))
    assert not f.stats.stage_reused
    same(f, fresh(a, moved, RenderSettings(sh_degree=1), staged), "sh 1")
    b = gb.load(shared_scene("biker.compressed.ply"))
    r.upload(b)  # another scene, the same camera
    f = r.render(moved, s)
    assert not f.stats.stage_reused
    same(f, fresh(b, moved, s, staged), "other scene")
    # the first scene modified and uploaded again: the same splat count, other colours and positions
    c = gb.Scene.from_arrays(a.means + np.float32(0.01), a.scales, a.quats, a.opacities, a.sh[:, ::-1].copy())
    r.upload(c)
    f = r.render(moved, s)
    assert not f.stats.stage_reused
    same(f, fresh(c, moved, s, staged), "modified scene")
    assert not np.array_equal(f.rgb, fresh(a, moved, s, staged).rgb)


def test_render_many_partials_and_progress_end_equal_to_the_frames():
    scene = gb.load(shared_scene("biker.compressed.ply"))
    cam = gb.orbit_camera(scene, 30, 20, width=160, height=120)
    jobs = [(cam, RenderSettings.parse(s)) for s in ("scalar", "gaussian_blending:2")]
    parts = [np.zeros((120, 160, 3), np.float32) for _ in jobs]
    seen: list[tuple[int, int, int]] = []
    r = create_renderer("cpu")
    r.upload(scene)
    frames = r.render_many(jobs, on_progress=lambda k, d, t: seen.append((k, d, t)), partials=parts)
    for p, f in zip(parts, frames):
        np.testing.assert_array_equal(p, f.rgb)
    assert {k for k, _, _ in seen} == {0, 1}
    last = {k: (d, t) for k, d, t in seen}
    assert all(d == t for d, t in last.values())
    ks = [k for k, _, _ in seen]  # the tiles interleaved: frame 1's first tiles come before frame 0's last
    assert ks.index(1) < len(ks) - 1 - ks[::-1].index(0), ks


def test_a_cancelled_render_many_raises_and_the_next_render_is_exact():
    scene = gb.load(shared_scene("plant.splat"))
    cam = gb.orbit_camera(scene, 30, 20, width=400, height=300)
    jobs = [(cam, RenderSettings.parse(s)) for s in ("scalar:3", "gaussian_blending:3")]
    r = create_renderer("cpu")
    r.upload(scene)
    want = r.render_many(jobs)
    total = want[0].stats.total_ms
    for at in (total * 0.02, total * 0.3, total * 0.8):
        token = gb.CancelToken()
        timer = threading.Timer(at / 1e3, token.set)
        timer.start()
        try:
            got = r.render_many(jobs, cancel=token)
            for a, b in zip(got, want):
                same(a, b, f"complete at {at:.0f} ms")
        except gb.RenderCancelled:
            pass
        timer.join()
        same(r.render(*jobs[1]), want[1], f"after a cancel at {at:.0f} ms")


def test_partials_must_match_the_jobs():
    scene = gb.load(shared_scene("biker.compressed.ply"))
    cam = gb.orbit_camera(scene, 30, 20, width=32, height=24)
    r = create_renderer("cpu")
    r.upload(scene)
    with pytest.raises(gb.RenderError, match="one array or None per job"):
        r.render_many([(cam, RenderSettings())], partials=[None, None])


@pytest.mark.parametrize("dilation, pre_dilation", [(400.0, 0.0), (0.3, 400.0)])
def test_a_wide_view_filter_keeps_splats_the_stage_would_call_off_screen(staged, dilation, pre_dilation):
    """A splat 8 px beyond the right edge, tiny on its own (3DGS's box: 5 px): a scalar view filter of +400 px^2
    spreads it into the image. The narrow image equals the same columns of a wider image (same cx; the splat on
    screen, inside both frustum clamps of the EWA Jacobian), where the stage's on-screen bound cannot cull it; a
    3DGS-filter frame of the same camera (another stage reach) sees nothing."""
    scene = gb.Scene.from_arrays(
        np.array([[8 / 3, 0.0, 4.0]]),
        np.full((1, 3), 0.01),
        np.array([[1.0, 0, 0, 0]]),
        np.array([0.9]),
        np.full((1, 1, 3), 0.5),
    )
    narrow = gb.Camera(64, 48, 60.0, 60.0, 32.0, 24.0, np.eye(3), np.zeros(3))
    wide = gb.Camera(160, 48, 60.0, 60.0, 32.0, 24.0, np.eye(3), np.zeros(3))
    wide_filter = RenderSettings(view_filter=ViewFilter(dilation, pre_dilation=pre_dilation))
    r = create_renderer(staged)
    r.upload(scene)
    plain, f = r.render_many([(narrow, RenderSettings()), (narrow, wide_filter)])
    assert plain.stats.visible == 0 and f.stats.visible == 1 and f.alpha.max() > 0.05
    ref = fresh(scene, wide, wide_filter, staged)
    assert np.array_equal(f.rgb, ref.rgb[:, :64]) and np.array_equal(f.alpha, ref.alpha[:, :64])


def test_order_reused_says_which_frames_binned_in_an_earlier_frames_depth_order():
    scene = gb.load(shared_scene("angel.compressed.ply"))
    cam = gb.orbit_camera(scene, 10, 20, width=96, height=72)
    r = create_renderer("cpu")
    r.upload(scene)
    specs = ["wsr", "scalar", "gaussian_blending", "scalar:2"]
    frames = r.render_many([(cam, RenderSettings.parse(s)) for s in specs])
    # wsr bins without an order; scalar sorts the stage's; gaussian_blending reuses it; x1 at 2x2 is another stage
    assert [f.stats.order_reused for f in frames] == [False, False, True, False]
    assert r.render(cam, RenderSettings.parse("mip")).stats.order_reused  # a later call: the kept stage's order
    f = r.render(gb.orbit_camera(scene, 11, 20, width=96, height=72), RenderSettings.parse("mip"))  # a new camera
    assert not f.stats.stage_reused and not f.stats.order_reused
