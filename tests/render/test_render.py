"""The render API: renderer reuse without keeping scenes alive; one renderer shared by threads."""

from __future__ import annotations

import gc
import threading
import weakref

import numpy as np
import pytest
from helpers import front_camera, random_scene, run_threads, skip_or_fail

import gbviewer as gb
from gbviewer.render import BACKENDS


def test_get_renderer_reuses_and_releases_scenes():
    cam = front_camera()
    first = random_scene(50, seed=0)
    a = gb.render(first, cam, "scalar").rgb
    assert gb.get_renderer(first, "cpu") is gb.get_renderer(first, "cpu")  # no second upload
    gone = weakref.ref(first)
    second = random_scene(50, seed=1)
    b = gb.render(second, cam, "scalar").rgb
    del first
    gc.collect()
    assert gone() is None  # the cache holds the last scene only
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(gb.render(second, cam, "scalar").rgb, b)


CONCURRENT_SPECS = ["scalar", "mip", "analytic", "gaussian_blending", "scalar:2", "wsr", "duplex"]


def check_concurrent_renders(backend: str, scene: gb.Scene, threads: int = 2, rounds: int = 2) -> None:
    """`threads` threads render every (camera, mode) job `rounds` times with the process's one renderer of `backend`,
    starting together, each in another order (so different modes run at the same time, duplex's cells included);
    every frame must equal the same job rendered alone, bit for bit, stats included."""
    cams = [front_camera(96, 72), front_camera(80, 56, f=45.0)]
    jobs = [
        (cam, gb.RenderSettings.parse(spec, background=(0.2, 0.3, 0.4))) for cam in cams for spec in CONCURRENT_SPECS
    ]
    renderer = gb.get_renderer(scene, backend)
    alone = [renderer.render(cam, settings) for cam, settings in jobs]
    barrier = threading.Barrier(threads)
    results: list[tuple[int, gb.Frame]] = []

    def work(t: int) -> None:
        order = [(j + t * len(jobs) // threads) % len(jobs) for j in range(len(jobs))]
        barrier.wait()
        for _ in range(rounds):
            for j in order:
                results.append((j, renderer.render(*jobs[j])))

    run_threads(work, threads)
    assert len(results) == threads * rounds * len(jobs)
    for j, frame in results:
        ref = alone[j]
        where = f"{backend} {jobs[j][1].spec} {jobs[j][0].width}x{jobs[j][0].height}"
        assert np.array_equal(frame.rgb, ref.rgb) and np.array_equal(frame.alpha, ref.alpha), where
        assert np.array_equal(frame.debug["evals"], ref.debug["evals"]), where
        for key in ("visible", "sort_length", "pairs", "evaluations"):
            assert getattr(frame.stats, key) == getattr(ref.stats, key), f"{where}: {key}"


def test_get_renderer_names_its_scene_argument():
    with pytest.raises(gb.GBViewerError, match=r"^get_renderer: the first argument is the scene .* got str 'cpu'$"):
        gb.get_renderer("cpu")  # a backend name where the scene goes


def test_concurrent_renders_cpu():
    """Two Python threads sharing the process's CPU renderer (its frames are serialised, each on every core)."""
    check_concurrent_renders("cpu", random_scene(400, seed=5, sh_degree=1))


_OOM_SCRIPT = r"""
import resource, numpy as np, gbviewer as gb
n = 6000
rng = np.random.default_rng(0)
scene = gb.Scene.from_arrays(np.c_[rng.uniform(-0.1, 0.1, (n, 2)), np.full(n, 3.0)], np.full((n, 3), 50.0),
                             np.tile([1.0, 0, 0, 0], (n, 1)), np.full(n, 0.5), np.full((n, 1, 3), 0.2))
cam = gb.Camera(1024, 1024, 500.0, 500.0, 512.0, 512.0, np.eye(3), np.zeros(3))
gb.render(scene, cam.with_size(32, 32))  # starts the thread pool before the limit
vm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmSize")) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 400 * 2**20, resource.RLIM_INFINITY))
try:
    gb.render(scene, cam, supersample=2)  # 6000 splats x 16384 tiles: 98M tile-list ids, 393 MB
except MemoryError:
    print("MemoryError")
"""


def test_tile_list_that_does_not_fit_is_a_memory_error(tmp_path):
    """A frame whose tile lists exceed the memory left raises MemoryError; nothing aborts inside the parallel
    binning."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", _OOM_SCRIPT], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.strip() == "MemoryError", (res.returncode, res.stdout, res.stderr[-2000:])


@pytest.mark.parametrize("backend", ["cpu", "glsl"])
def test_releasing_a_shared_handle_keeps_every_handle_rendering(backend):
    """`get_renderer(...).release()` frees the process's shared renderer; the next frame of any handle (and
    `gb.render`) uploads its scene again instead of rendering without one."""
    ok, why = BACKENDS[backend].available()
    if not ok:
        skip_or_fail(f"{backend} unavailable: {why}")
    scene, cam = random_scene(200, seed=4), front_camera(48, 32)
    handle = gb.get_renderer(scene, backend)
    a = handle.render(cam, gb.RenderSettings())
    handle.release()
    np.testing.assert_array_equal(gb.render(scene, cam, backend=backend).rgb, a.rgb)
    handle.release()
    np.testing.assert_array_equal(handle.render(cam, gb.RenderSettings()).rgb, a.rgb)


def test_release_buffers():
    """The CPU renderer keeps its native per-frame buffers between frames of a scene (uploading the same scene again
    keeps them) and frees them when another scene is uploaded; frames after that are unchanged."""
    from gbviewer.render import CpuRenderer

    scene, cam = random_scene(200, seed=4), front_camera()
    r = CpuRenderer()
    r.upload(scene)
    a = r.render(cam, gb.RenderSettings())
    kept = r._impl.buffer_bytes
    assert kept > 0
    r.upload(scene)
    assert r._impl.buffer_bytes == kept
    r.upload(random_scene(10, seed=5))
    assert r._impl.buffer_bytes == 0
    r.upload(scene)
    np.testing.assert_array_equal(r.render(cam, gb.RenderSettings()).rgb, a.rgb)


def test_renders_of_two_scenes_from_many_threads_get_their_own_scene():
    """gb.render, a handle from gb.get_renderer kept across calls, and gb.trace_pixel, from several threads with two
    scenes and a tiny switch interval: every frame (and trace) is its own scene's, bit for bit (the process's
    renderer is shared; each call uploads its own scene under the backend's lock when another one is uploaded)."""
    import sys

    cam = front_camera(32, 24)
    scenes = [random_scene(60, seed=21), random_scene(50, seed=22, sh_degree=1)]
    modes = ["scalar", "duplex"]
    refs = {(i, m): gb.render(s, cam, m) for i, s in enumerate(scenes) for m in modes}
    traces = {i: gb.trace_pixel(s, cam, 16, 12).to_json() for i, s in enumerate(scenes)}
    assert not np.array_equal(refs[0, "scalar"].rgb, refs[1, "scalar"].rgb) and traces[0] != traces[1]
    threads = 4
    barrier = threading.Barrier(threads)
    wrong: list[str] = []

    def work(t: int) -> None:
        own = t % 2
        handle = gb.get_renderer(scenes[own])
        barrier.wait()
        for k in range(120):
            m = modes[(k // 3) % 2]
            if k % 3 == 0:
                i = (t + k) % 2
                frame = gb.render(scenes[i], cam, m)
            elif k % 12 == 1:
                i = (t + k) % 2
                if gb.trace_pixel(scenes[i], cam, 16, 12).to_json() != traces[i]:
                    wrong.append(f"thread {t}: trace {k} of scene {i}")
                continue
            else:
                i, frame = own, handle.render(cam, gb.RenderSettings.parse(m))
            if not (np.array_equal(frame.rgb, refs[i, m].rgb) and np.array_equal(frame.alpha, refs[i, m].alpha)):
                wrong.append(f"thread {t}: frame {k} ({m}) of scene {i}")

    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        run_threads(work, threads)
    finally:
        sys.setswitchinterval(before)
    assert not wrong, f"{len(wrong)} of {threads * 120} calls: {wrong[:5]}"


def test_a_frame_beyond_int32_samples_is_one_line(bundled_scene):
    """16384 x 16384 at supersample 8 would overflow the native modules' int32 indices: a RenderError, not the
    binding's ValueError."""
    cam = gb.orbit_camera(bundled_scene, width=16384, height=16384)
    with pytest.raises(gb.RenderError, match="^16384x16384 at supersample 8: .* samples, more than"):
        gb.render(bundled_scene, cam, "scalar", supersample=8)


def test_render_many_of_a_handle_draws_its_own_scene():
    """A handle's render_many went to the shared renderer as it stood: after another scene's render it drew that
    scene (and ran outside the backend's lock). It uploads its own scene first, as render does."""
    cam = front_camera(32, 24)
    a, b = random_scene(60, seed=31), random_scene(60, seed=32)
    handle = gb.get_renderer(a, "cpu")
    own = handle.render(cam, gb.RenderSettings()).rgb
    gb.get_renderer(b, "cpu").render(cam, gb.RenderSettings())
    (frame,) = handle.render_many([(cam, gb.RenderSettings())])
    assert np.array_equal(frame.rgb, own)


@pytest.mark.parametrize("call", ["render str camera", "render str settings", "trace", "render_many triple"])
def test_a_frame_of_other_types_is_one_line(call):
    """A handle's frame of a camera or settings of another type raised AttributeError (or an unpacking error)
    from inside the backend; it is one line naming the call, before the backend's lock."""
    scene = random_scene(20, seed=33)
    cam, handle = front_camera(8, 8), gb.get_renderer(scene, "cpu")
    calls = {
        "render str camera": lambda: gb.render(scene, "front"),
        "render str settings": lambda: handle.render(cam, "scalar"),
        "trace": lambda: handle.trace(None, gb.RenderSettings(), 1, 1),
        "render_many triple": lambda: handle.render_many([(cam, gb.RenderSettings(), 1)]),
    }
    with pytest.raises(gb.GBViewerError, match=r"expected a gbviewer.Camera and a RenderSettings"):
        calls[call]()
    assert handle.render(camera=cam, settings=gb.RenderSettings()).rgb.shape == (8, 8, 3)
