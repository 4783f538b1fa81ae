"""Cancelling a render (`cancel=threading.Event`) and following it (`on_progress(done, total)`), on every backend
this machine has: the native CPU module skips its remaining tiles once the flag is set, GPU backends stop between
dispatches, and a render that is followed but not cancelled gives the same frame as one that is not."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from helpers import front_camera, random_scene

import gbviewer as gb
from gbviewer.render.glsl import GlslRenderer


@pytest.fixture(scope="module")
def scene() -> gb.Scene:
    return random_scene(400, seed=3)


def _settings(mode="gaussian_blending", ss=1) -> gb.RenderSettings:
    return gb.RenderSettings(gb.Mode.parse(mode), ss)


def _renderer(backend: str, scene: gb.Scene):
    if backend == "glsl":
        ok, why = GlslRenderer.available()
        if not ok:
            pytest.skip(f"no OpenGL 4.3 here: {why}")
    return gb.get_renderer(scene, backend)


@pytest.mark.parametrize("backend", ["cpu", pytest.param("glsl", marks=pytest.mark.gl)])
@pytest.mark.parametrize("ss", [1, 3])
def test_progress_is_reported_and_the_frame_unchanged(scene, backend, ss):
    r = _renderer(backend, scene)
    cam = front_camera(96, 64)
    plain = r.render(cam, _settings(ss=ss))
    seen: list[tuple[int, int]] = []
    followed = r.render(cam, _settings(ss=ss), cancel=threading.Event(), on_progress=lambda d, t: seen.append((d, t)))
    np.testing.assert_array_equal(followed.rgb, plain.rgb)
    np.testing.assert_array_equal(followed.alpha, plain.alpha)
    done, total = seen[-1]
    assert done == total > 0 and all(t == total and 0 <= d <= total for d, t in seen)
    if backend == "cpu":  # tiles of the (supersampled) frame
        assert total == -(-96 * ss // 16) * -(-64 * ss // 16)


@pytest.mark.parametrize("backend", ["cpu", pytest.param("glsl", marks=pytest.mark.gl)])
def test_a_set_event_stops_the_render(scene, backend):
    r = _renderer(backend, scene)
    cancel = threading.Event()
    cancel.set()
    seen: list[tuple[int, int]] = []
    with pytest.raises(gb.RenderCancelled):
        r.render(front_camera(96, 64), _settings(), cancel=cancel, on_progress=lambda d, t: seen.append((d, t)))
    assert seen == []  # refused before the first tile or dispatch: no progress was ever reported
    assert issubclass(gb.RenderCancelled, gb.GBViewerError)


def test_event_set_during_the_render_cancels_it(scene):
    """Set from the progress callback, i.e. while the blend runs: the call raises instead of returning a frame."""
    cancel = threading.Event()
    with pytest.raises(gb.RenderCancelled):
        gb.render(
            scene,
            front_camera(320, 240),
            "gaussian_blending",
            supersample=2,
            cancel=cancel,
            on_progress=lambda done, total: cancel.set(),
        )
    frame = gb.render(scene, front_camera(320, 240), "gaussian_blending", supersample=2)  # the renderer still works
    assert np.isfinite(frame.rgb).all() and frame.rgb.max() > 0


@pytest.mark.parametrize("ss", [1, 2])
def test_native_module_skips_every_tile_once_the_flag_is_set(scene, ss):
    """The cancel flag of the native call itself: with it set, no tile is blended (no progress past 0 is reported;
    the image planes are left unwritten, not zero-filled: image.h), and the result says it was cancelled."""
    from gbviewer import _native
    from gbviewer.render.prepare import camera_args

    cam = front_camera(64, 48)
    r = _native.Renderer()
    r.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, None)
    flag = np.array([1], np.int64)
    seen: list[tuple[int, int]] = []
    args = (*camera_args(cam), int(gb.Mode.SCALAR), ss, 3, np.zeros(3, np.float32), False)
    out = r.render(*args, cancel=flag, on_progress=lambda d, t: seen.append((d, t)))
    assert out["cancelled"] and all(d == 0 for d, _ in seen)
    flag[0] = 0
    out = r.render(*args, cancel=flag, on_progress=lambda d, t: seen.append((d, t)))
    assert not out["cancelled"] and seen[-1] == (-(-64 * ss // 16) * -(-48 * ss // 16),) * 2 and out["rgb"].any()


@pytest.mark.parametrize("backend", ["cpu", pytest.param("glsl", marks=pytest.mark.gl)])
@pytest.mark.parametrize("ss", [1, 2, 3])
def test_partial_frame_ends_equal_to_the_frame(scene, backend, ss):
    """`partial` holds the finished frame once the render returns: exactly, except (ss=3 on the CPU) output pixels
    whose samples straddle two tiles, which hold one tile's share until the frame replaces them."""
    r = _renderer(backend, scene)
    cam = front_camera(100, 70)
    partial = np.full((70, 100, 3), np.nan, np.float32)
    frame = r.render(cam, _settings(ss=ss), partial=partial)
    exact = np.ones((70, 100), bool)
    if backend == "cpu" and 16 % ss:

        def one_tile(n: int) -> np.ndarray:  # output pixels along an axis whose samples lie in one tile
            return np.ptp(np.arange(n * ss).reshape(-1, ss) // 16, axis=1) == 0

        exact = np.outer(one_tile(70), one_tile(100))
        assert 0.5 < exact.mean() < 1 and np.isfinite(partial).all()
    np.testing.assert_array_equal(partial[exact], frame.rgb[exact])


def test_partial_tiles_of_a_cancelled_render_equal_the_final_tiles(scene):
    """Cancelled at the first report of a finished tile: the tiles written so far are the final frame's, the rest
    untouched, and they were blended from the centre out."""
    cam = front_camera(640, 480)
    final = gb.render(scene, cam, "gaussian_blending", supersample=2)
    partial = np.full((480, 640, 3), np.nan, np.float32)
    cancel = threading.Event()
    with pytest.raises(gb.RenderCancelled):
        gb.render(
            scene,
            cam,
            "gaussian_blending",
            supersample=2,
            cancel=cancel,
            partial=partial,
            on_progress=lambda done, total: done and cancel.set(),
        )
    filled = np.isfinite(partial).all(axis=2)
    assert filled.any() and not filled.all()
    np.testing.assert_array_equal(partial[filled], final.rgb[filled])
    tiles = filled[::8, ::8]  # one entry per 16x16 tile of the 2x2-supersampled frame (8x8 output pixels)
    ty, tx = np.mgrid[0 : tiles.shape[0], 0 : tiles.shape[1]]
    dist = np.hypot(tx + 0.5 - tiles.shape[1] / 2, ty + 0.5 - tiles.shape[0] / 2)
    assert dist[tiles].max() <= dist[~tiles].min() + 2.0  # centre out (up to the tiles in flight)


def test_a_partial_buffer_of_the_wrong_shape_is_refused(scene):
    with pytest.raises(gb.RenderError, match=r"partial: expected .*\(48, 64, 3\)"):
        gb.render(scene, front_camera(64, 48), partial=np.zeros((48, 64, 4), np.float32))
    with pytest.raises(gb.RenderError, match="partial"):
        gb.render(scene, front_camera(64, 48), partial=np.zeros((48, 64, 3), np.float64))


class _NotCallable:
    is_set = True


@pytest.mark.parametrize("cancel", [object(), True, lambda: False, "stop", _NotCallable()])
def test_a_cancel_without_is_set_is_refused(scene, cancel):
    """Not a raw AttributeError from inside the render: one RenderError naming `cancel` and what it takes."""
    with pytest.raises(
        gb.RenderError,
        match=r"^cancel: expected a gbviewer.CancelToken, a threading.Event or an "
        r"object with an is_set\(\) method \(or None\), got \w+$",
    ):
        gb.render(scene, front_camera(64, 48), "scalar", cancel=cancel)


def test_a_cancel_token_set_during_the_render_cancels_it(scene):
    """gb.CancelToken: the native loop reads its flag directly (no helper thread); set from another thread while
    the frame is being blended, the call raises RenderCancelled, and the renderer still works afterwards."""
    token = gb.CancelToken()
    started = threading.Event()

    def setter() -> None:
        started.wait(60)
        token.set()

    helper = threading.Thread(target=setter)
    helper.start()
    with pytest.raises(gb.RenderCancelled):
        gb.render(
            scene,
            front_camera(640, 480),
            "gaussian_blending",
            supersample=3,
            cancel=token,
            on_progress=lambda done, total: started.set(),
        )
    helper.join()
    assert token.is_set() and token.wait(0)
    token.clear()
    assert not token.is_set() and not token.wait(0.01)
    frame = gb.render(scene, front_camera(96, 64), cancel=token)
    np.testing.assert_array_equal(frame.rgb, gb.render(scene, front_camera(96, 64)).rgb)


def test_no_helper_thread_runs_during_a_render(scene):
    """Progress is reported from the rendering thread itself, and no thread is started for the render."""
    before = set(threading.enumerate())
    seen: list[tuple[threading.Thread, set[threading.Thread]]] = []
    gb.render(
        scene,
        front_camera(320, 240),
        "gaussian_blending",
        supersample=2,
        cancel=threading.Event(),
        on_progress=lambda done, total: seen.append((threading.current_thread(), set(threading.enumerate()))),
    )
    assert seen and all(t is threading.current_thread() and during <= before for t, during in seen)


@pytest.mark.parametrize("backend", ["cpu", pytest.param("glsl", marks=pytest.mark.gl)])
def test_a_raising_progress_callback_ends_the_render_with_one_error(scene, backend):
    """on_progress raising: the call ends with CallbackError chained to the callback's exception, no tile is blended
    after it, and the renderer (and a later cancel) still works."""
    r = _renderer(backend, scene)
    cam = front_camera(320, 240)
    plain = r.render(cam, _settings())
    calls: list[int] = []

    def boom(done: int, total: int) -> None:
        calls.append(done)
        raise ZeroDivisionError("boom")

    with pytest.raises(gb.CallbackError, match="on_progress raised ZeroDivisionError: boom") as info:
        r.render(cam, _settings(ss=2), on_progress=boom)
    assert isinstance(info.value.__cause__, ZeroDivisionError) and len(calls) == 1
    cancel = gb.CancelToken()
    cancel.set()
    with pytest.raises(gb.RenderCancelled):
        r.render(cam, _settings(), cancel=cancel)
    np.testing.assert_array_equal(r.render(cam, _settings()).rgb, plain.rgb)


class SetOnSecondLook(threading.Event):
    """An Event that reads as set from its second is_set() on (the first is the render's check before any work)."""

    def __init__(self) -> None:
        super().__init__()
        self.looks = 0

    def is_set(self) -> bool:
        self.looks += 1
        return self.looks > 1 or super().is_set()


def test_a_plain_event_is_bridged_by_the_rendering_thread(scene):
    """Without on_progress, a threading.Event is still seen mid-frame: the native loop's report (on the calling
    thread) copies it into the render's flag, and the frame stops with RenderCancelled."""
    event = SetOnSecondLook()
    partial = np.full((480, 640, 3), np.nan, np.float32)
    with pytest.raises(gb.RenderCancelled):  # 10800 tiles: many report intervals (5 ms) long
        gb.render(scene, front_camera(640, 480), "gaussian_blending", supersample=3, cancel=event, partial=partial)
    assert event.looks >= 2 and not np.isfinite(partial).all()  # stopped before the last tile


def test_rendering_from_inside_on_progress_with_the_same_renderer_is_an_error_not_a_hang(scene):
    """on_progress that renders with the renderer already rendering (here the process's one, through gb.render)
    would wait for itself: that inner call raises, and the outer one ends with the CallbackError it caused. With a
    renderer of its own the callback may render."""
    cam = front_camera(320, 240)

    def nested(done: int, total: int) -> None:
        gb.render(scene, front_camera(16, 16))

    with pytest.raises(gb.CallbackError, match="on_progress raised RenderError: a frame was started from inside"):
        gb.render(scene, cam, on_progress=nested)
    from gbviewer.render import create_renderer

    own = create_renderer("cpu")
    own.upload(scene)
    inner: list[gb.Frame] = []
    frame = gb.render(
        scene, cam, on_progress=lambda d, t: inner.append(own.render(front_camera(16, 16), gb.RenderSettings()))
    )
    np.testing.assert_array_equal(frame.rgb, gb.render(scene, cam).rgb)
    assert inner and all(np.array_equal(f.rgb, inner[0].rgb) for f in inner)
