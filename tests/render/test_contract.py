"""The backend contract (`gbviewer.render.contract.Renderer`): one behavioural suite run over every registered backend
(`BACKENDS`, so a new backend is checked by its one registry line): render, cancel, progress, partial, release,
re-upload, use from two threads, and each of its `Capabilities` honoured. A backend that cannot run here (cuda
without a GPU) skips with its reason."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from helpers import run_threads

import gbviewer as gb
from gbviewer.bench import SIMD_NAMES
from gbviewer.core.errors import BackendFailed, RenderCancelled, RenderError
from gbviewer.render import BACKENDS, Capabilities, Renderer, RenderSettings, capable, create_gl_context, get_renderer
from gbviewer.render.glsl.context import standalone_context

GB = RenderSettings("gaussian_blending")
TILED = RenderSettings("gaussian_blending", supersample=2)  # at 320x240: 1200 tiles, progress and partial between


def runnable(name: str) -> type[Renderer]:
    cls = BACKENDS[name]
    ok, why = cls.available()
    if not ok:
        pytest.skip(f"{name} backend unavailable here: {why}")
    return cls


@pytest.fixture(params=list(BACKENDS))
def backend(request) -> type[Renderer]:
    return runnable(request.param)


@pytest.fixture
def renderer(backend, bundled_scene):
    r = backend()
    r.upload(bundled_scene)
    yield r
    r.release()


def view(scene: gb.Scene, w: int = 96, h: int = 72, azimuth: float = 30.0) -> gb.Camera:
    return gb.orbit_camera(scene, azimuth, 15, width=w, height=h)


def long_render(renderer: Renderer, scene: gb.Scene) -> tuple[gb.Camera, RenderSettings]:
    """A frame with many tiles where the backend reports tiles (`progressive`), else a small one (a GPU backend
    reports its dispatches: llvmpipe's are slow enough to be seen between)."""
    if renderer.capabilities.progressive:
        return view(scene, 320, 240), TILED
    return view(scene), GB


def half(scene: gb.Scene) -> gb.Scene:
    """Every other splat of `scene`: another scene with other pixels."""
    return gb.Scene.from_arrays(
        scene.means[::2],
        scene.scales[::2],
        scene.quats[::2],
        scene.opacities[::2],
        scene.sh[::2],
        None if scene.filter_3d is None else scene.filter_3d[::2],
    )


def test_the_contract_is_declared(backend):
    assert isinstance(backend.capabilities, Capabilities) and backend.name in BACKENDS
    assert issubclass(backend, Renderer) and not getattr(backend, "__abstractmethods__", None)
    caps = backend.capabilities
    assert callable(getattr(backend, "render_to_texture", None)) == caps.gl_texture
    assert callable(getattr(backend, "trace", None)) == caps.trace
    assert callable(getattr(backend, "check_context", None)) or not caps.gl_context


def test_render_is_a_deterministic_frame_close_to_the_cpu(renderer, bundled_scene):
    cam = view(bundled_scene)
    frame = renderer.render(cam, GB)
    assert frame.rgb.shape == (72, 96, 3) and frame.alpha.shape == (72, 96) and frame.rgb.dtype == np.float32
    assert np.isfinite(frame.rgb).all() and frame.rgb.std() > 0.01 and 0 <= frame.alpha.min() <= frame.alpha.max() <= 1
    assert frame.stats.backend == renderer.name and frame.stats.visible > 0
    np.testing.assert_array_equal(renderer.render(cam, GB).rgb, frame.rgb)
    assert np.abs(frame.rgb - gb.render(bundled_scene, cam, "gaussian_blending").rgb).mean() < 1e-3


def test_a_set_cancel_event_raises_and_the_renderer_renders_on(renderer, bundled_scene):
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(RenderCancelled):
        renderer.render(view(bundled_scene), GB, cancel=cancel)
    assert renderer.render(view(bundled_scene), GB, cancel=threading.Event()).rgb.std() > 0.01


def test_cancel_set_while_rendering_stops_the_render(renderer, bundled_scene):
    cancel, seen = threading.Event(), []

    def on_progress(done: int, total: int) -> None:
        if done < total:  # seen while it renders
            seen.append(done)
            cancel.set()

    try:
        renderer.render(*long_render(renderer, bundled_scene), cancel=cancel, on_progress=on_progress)
    except RenderCancelled:
        return
    if not seen:
        pytest.skip("the render finished within one progress poll: nothing to cancel")
    pytest.fail(f"cancelled at {seen[0]} tiles, the render still returned its frame")


def test_progress_counts_up_to_its_total(renderer, bundled_scene):
    calls: list[tuple[int, int]] = []
    renderer.render(*long_render(renderer, bundled_scene), on_progress=lambda d, t: calls.append((d, t)))
    assert calls and calls[-1][0] == calls[-1][1] > 0
    assert len({t for _, t in calls}) == 1 and all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))


def test_partial_receives_the_frame_progressively_only_where_promised(renderer, bundled_scene):
    """`partial` ends equal to the frame. While the render runs (done < total), a progressive backend's partial
    holds some finished pixels; any other backend's is untouched until the end."""
    cam, settings = long_render(renderer, bundled_scene)
    partial = np.full((cam.height, cam.width, 3), np.nan, np.float32)
    filled: list[float] = []

    def on_progress(done: int, total: int) -> None:
        if done < total:
            filled.append(float(np.isfinite(partial).all(axis=2).mean()))

    frame = renderer.render(cam, settings, on_progress=on_progress, partial=partial)
    np.testing.assert_array_equal(partial, frame.rgb)
    if renderer.capabilities.progressive:
        assert any(0 < f < 1 for f in filled), filled
    else:
        assert all(f == 0 for f in filled), filled
    with pytest.raises(RenderError, match="partial"):
        renderer.render(cam, GB, partial=np.zeros((10, 10, 3), np.float32))


def test_release_then_upload_renders_the_same_and_release_twice_is_harmless(renderer, bundled_scene):
    cam = view(bundled_scene)
    first = renderer.render(cam, GB)
    renderer.release()
    renderer.release()
    with pytest.raises(RenderError):
        renderer.render(cam, GB)  # nothing uploaded any more
    renderer.upload(bundled_scene)
    np.testing.assert_array_equal(renderer.render(cam, GB).rgb, first.rgb)


def test_re_upload_switches_scenes(backend, renderer, bundled_scene):
    cam = view(bundled_scene)
    first = renderer.render(cam, GB).rgb
    other = half(bundled_scene)
    renderer.upload(other)
    fresh = backend()
    fresh.upload(other)
    expected = fresh.render(cam, GB).rgb
    fresh.release()
    got = renderer.render(cam, GB).rgb
    np.testing.assert_array_equal(got, expected)
    assert not np.array_equal(got, first)
    renderer.upload(bundled_scene)
    np.testing.assert_array_equal(renderer.render(cam, GB).rgb, first)


def test_two_threads_render_at_once(backend, renderer, bundled_scene):
    """Without a GL context one renderer serves both threads; a GL-context backend's renderer belongs to its
    context's thread, so each thread makes its own on a context of its own."""
    cams = [view(bundled_scene, azimuth=a) for a in (0.0, 120.0)]
    expected = [renderer.render(c, GB).rgb for c in cams]
    got: dict[tuple[int, int], np.ndarray] = {}
    start = threading.Barrier(2)

    def work(k: int) -> None:
        ctx = create_gl_context() if backend.capabilities.gl_context else None
        own = backend(ctx=ctx) if ctx is not None else renderer
        if ctx is not None:
            own.upload(bundled_scene)
        start.wait()
        for j in range(len(cams)):  # the threads in opposite orders
            i = (j + k) % len(cams)
            got[k, i] = own.render(cams[i], GB).rgb
        if ctx is not None:
            own.release()
            ctx.release()

    run_threads(work, 2)
    assert len(got) == 2 * len(cams)  # every thread rendered every view
    for (_, j), rgb in got.items():
        np.testing.assert_array_equal(rgb, expected[j])


@pytest.mark.parametrize("name", capable("gl_texture"))
def test_gl_texture_holds_the_frame(name, bundled_scene):
    """A backend that renders into GL textures writes what `render` returns; one that needs a GL context takes
    one and says whether it will do."""
    backend = runnable(name)
    ctx = standalone_context()  # the process's headless context, current in this thread (never released)
    if backend.capabilities.gl_context:
        assert backend.check_context(ctx) == (True, "")
        r = backend(ctx=ctx)
    else:
        ok, why = backend.gl_interop()
        if not ok:
            pytest.skip(f"{name} cannot write this context's textures: {why}")
        r = backend()
    r.upload(bundled_scene)
    cam = view(bundled_scene, 97, 61)
    tex = ctx.texture((97, 61), 4, dtype="f4")
    stats = r.render_to_texture(tex, cam, GB)
    frame = r.render(cam, GB)
    img = np.frombuffer(tex.read(), np.float32).reshape(61, 97, 4)
    np.testing.assert_array_equal(img[:, :, :3], frame.rgb)
    np.testing.assert_array_equal(img[:, :, 3], frame.alpha)
    assert stats.visible == frame.stats.visible and stats.backend == name
    r.release_texture(tex.glo)
    tex.release()
    r.release()


def test_trace_and_simd_where_promised(renderer, bundled_scene):
    cam = view(bundled_scene)
    frame = renderer.render(cam, GB)
    caps = renderer.capabilities
    assert (frame.stats.simd in SIMD_NAMES) if caps.simd else frame.stats.simd is None
    if caps.trace:
        t = renderer.trace(cam, GB, 40, 30)
        np.testing.assert_allclose(t.color, frame.rgb[30, 40], atol=1e-5)


def test_usable_until_failed(renderer, bundled_scene):
    assert renderer.usable() == (True, "")
    err = renderer.failed("device lost")
    assert isinstance(err, BackendFailed) and "device lost" in str(err) and renderer.name in str(err)
    assert renderer.usable() == (False, "device lost")


def test_the_shared_renderer_that_stopped_working_is_replaced(backend, bundled_scene):
    first = get_renderer(bundled_scene, backend.name)
    assert get_renderer(bundled_scene, backend.name) is first
    first.failed("device lost")
    second = get_renderer(bundled_scene, backend.name)
    assert second is not first and second.usable() == (True, "")
    assert second.render(view(bundled_scene), GB).rgb.std() > 0.01


def test_render_many_equals_render_per_job(renderer, bundled_scene):
    """Every backend's render_many (the CPU's shared stage, or the contract's default loop over render) gives each
    job the frame `render` gives it, with progress per job."""
    cam = view(bundled_scene)
    jobs = [(cam, RenderSettings.parse(s)) for s in ("scalar", "gaussian_blending")] + [
        (view(bundled_scene, 64, 48), RenderSettings())
    ]
    seen: set[int] = set()
    frames = renderer.render_many(jobs, on_progress=lambda job, done, total: seen.add(job))
    assert len(frames) == len(jobs)
    for (c, s), f in zip(jobs, frames):
        ref = renderer.render(c, s)
        assert np.array_equal(f.rgb, ref.rgb) and np.array_equal(f.alpha, ref.alpha), f"{renderer.name} {s.spec}"
        assert (f.stats.visible, f.stats.pairs) == (ref.stats.visible, ref.stats.pairs)
    assert not renderer.capabilities.progressive or seen == {0, 1, 2}


def test_a_still_level_of_detail_camera_uploads_nothing(renderer, bundled_scene):
    """A level-of-detail frame draws its cut over the uploaded scene (the hierarchy goes up once): rendering a still
    camera again, and other panes of it (another mode; another supersampling), copies nothing to the backend
    (`Renderer.uploads`), the panes of one sampling grid share the per-camera stage, and every frame equals the
    cut's gathered Scene rendered by a renderer of the same backend."""
    cam = view(bundled_scene)
    specs = ("gaussian_blending+lod:2", "scalar+lod:2", "gaussian_blending:2+lod:2", "gaussian_blending+lod:2")
    first = renderer.render(cam, RenderSettings.parse(specs[0]))
    before = renderer.uploads
    assert before >= 1
    frames = [renderer.render(cam, RenderSettings.parse(s)) for s in specs]
    assert renderer.uploads == before
    gathered = gb.lod.cut_scene(bundled_scene, cam, 2.0)
    assert gathered.meta["lod"][0] < bundled_scene.num_splats  # the cut merged splats: not the scene itself
    ref = type(renderer)()
    ref.upload(gathered)
    try:
        for spec, frame in zip(specs, frames):
            want = ref.render(cam, RenderSettings.parse(spec.split("+")[0]))
            assert np.array_equal(frame.rgb, want.rgb) and np.array_equal(frame.alpha, want.alpha), spec
            assert frame.stats.lod_splats == gathered.meta["lod"][0], spec
    finally:
        ref.release()
    assert np.array_equal(frames[-1].rgb, first.rgb)
    if renderer.capabilities.shared_stage:
        assert [f.stats.stage_reused for f in frames] == [True, True, False, False]
