"""The glsl backend's machinery and API: its scan and radix sort, dispatch over two axes, buffer reuse, empty frames,
contexts (the app's, a missing one, another current one), storage limits and the command line."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from glsl_helpers import MAX_TOL, MEAN_TOL, awkward_scene, compare
from helpers import front_camera, random_scene

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.core.errors import BackendUnavailable, RenderError
from gbviewer.render import RenderSettings
from gbviewer.render.glsl import GlslRenderer, gpu, standalone_context
from gbviewer.render.glsl import context as gl_context
from gbviewer.render.glsl import interface as gi
from gbviewer.render.glsl.sort import radix_sort, scan

pytestmark = pytest.mark.gl


@pytest.mark.parametrize("n, bits, high", [(1, 4, 3), (5, 8, 4), (2049, 12, 100), (100_000, 32, 2**32), (70_000, 8, 7)])
def test_radix_sort_is_stable(gl, n, bits, high):
    r = GlslRenderer()
    rng = np.random.default_rng(n)
    keys = rng.integers(0, high, n, dtype=np.uint64).astype(np.uint32)
    bufs = [r.gpu.ensure(f"t{i}", n * 4) for i in range(4)]
    bufs[0].write(keys.tobytes())
    bufs[1].write(np.arange(n, dtype=np.uint32).tobytes())
    k, v = radix_sort(r.gpu, *bufs, n, bits)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(np.frombuffer(v.read(size=n * 4), np.uint32), order)
    np.testing.assert_array_equal(np.frombuffer(k.read(size=n * 4), np.uint32), keys[order])
    r.release()


@pytest.mark.parametrize("n", [1, 1023, 1024, 1025, 1024 * 1024 + 3])
def test_exclusive_scan(gl, n):
    r = GlslRenderer()
    data = np.random.default_rng(n).integers(0, 7, n).astype(np.uint32)
    buf = r.gpu.ensure("data", n * 4)
    buf.write(data.tobytes())
    r.gpu.ensure("totals", gi.TOTALS_BYTES).write(np.zeros(gi.TOTALS_SLOTS, np.uint32).tobytes())
    scan(r.gpu, buf, n, total_slot=gi.TOTAL_VISIBLE)
    expect = np.concatenate([[0], np.cumsum(data, dtype=np.uint64)[:-1]]).astype(np.uint32)
    np.testing.assert_array_equal(np.frombuffer(buf.read(size=n * 4), np.uint32), expect)
    assert np.frombuffer(r.gpu.buffers["totals"].read(), np.uint32)[gi.TOTAL_VISIBLE] == data.sum()
    r.release()


def test_dispatch_over_two_axes(gl, monkeypatch):
    """More than 65535 groups go over x and y (scenes of > 16.7M splats); force that path with a limit of 3."""
    monkeypatch.setattr(gpu, "MAX_GROUPS", 3)
    scene = awkward_scene(6, n=4000)
    r = GlslRenderer()
    r.upload(scene)
    for spec in ("scalar", "gaussian_blending:2"):
        compare(scene, front_camera(64, 48), spec, renderer=r)
    r.release()


# ---- buffers, scenes, contexts ------------------------------------------------------------------------------------


def test_buffers_reused_and_grown(gl):
    small, large = awkward_scene(4, n=300), awkward_scene(5, n=3000)
    cam, s = front_camera(64, 48), RenderSettings()
    r = GlslRenderer()
    r.upload(small)
    r.render(cam, s)
    first = r.allocations
    r.render(cam, s)
    assert r.allocations == first, "the second identical frame reallocated buffers"
    r.upload(large)  # a larger scene after a smaller one: buffers grow ...
    compare(large, cam, "scalar", renderer=r)
    compare(large, cam, "gaussian_blending", renderer=r)
    grown = r.allocations
    assert grown > first
    r.upload(small)  # ... and a smaller one reuses them
    compare(small, cam, "scalar", renderer=r)
    assert r.allocations == grown
    r.release()


def test_empty_frame(gl):
    scene = random_scene(50)
    cam = gb.Camera(32, 32, 30, 30, 16, 16, np.eye(3), [0.0, 0.0, -10.0])  # every splat behind the camera
    out = GlslRenderer()
    out.upload(scene)
    f = out.render(cam, RenderSettings(background=(0.5, 0.25, 1.0)))
    assert f.stats.visible == 0 and f.stats.sort_length == 0
    np.testing.assert_array_equal(f.rgb, np.broadcast_to(np.float32([0.5, 0.25, 1.0]), (32, 32, 3)))
    assert (f.alpha == 0).all() and (f.debug["evals"] == 0).all()


def test_existing_context(gl, bundled_scene):
    """An app passes its moderngl.Context (kept current in its thread); the renderer works in it."""
    ctx = standalone_context()  # stands in for the app's window context,
    with ctx:  # which the app keeps current in its thread
        r = GlslRenderer(ctx=ctx)
        r.upload(bundled_scene)
        cam, s = gb.orbit_camera(bundled_scene, width=48, height=40), RenderSettings.parse("gaussian_blending")
        frame = r.render(cam, s)
        ref = gb.get_renderer(bundled_scene, "cpu").render(cam, s)
        assert np.abs(frame.rgb - ref.rgb).mean() < MEAN_TOL
        assert np.abs(frame.rgb - ref.rgb).max() < MAX_TOL
        r.release()


def test_unavailable_is_clear(monkeypatch):
    monkeypatch.setattr(gl_context, "_standalone", {})
    registry = importlib.import_module("gbviewer.render.registry")
    monkeypatch.setattr(registry, "_renderers", {})  # none made while GL was there

    def no_egl():
        raise Exception("eglInitialize failed (0x3001)")

    monkeypatch.setattr(gl_context, "_new_context", no_egl)
    ok, why = GlslRenderer.available()
    assert not ok and "eglInitialize failed" in why and "OpenGL 4.3" in why and "libegl1" in why
    with pytest.raises(BackendUnavailable, match="eglInitialize failed"):
        GlslRenderer()
    with pytest.raises(BackendUnavailable, match="glsl backend unavailable"):
        gb.render(random_scene(10), front_camera(), backend="glsl")

    class OldContext:
        version_code = 410
        info = {"GL_RENDERER": "Old GPU"}

    with pytest.raises(BackendUnavailable, match=r"OpenGL 4\.1 \(Old GPU\).*4\.3"):
        GlslRenderer(ctx=OldContext())
    assert GlslRenderer.check_context(OldContext())[0] is False


def test_scene_too_large_is_clear(gl):
    r = GlslRenderer()
    r.gpu.max_block = 4096  # pretend a GPU whose storage buffers hold 4 KiB
    with pytest.raises(RenderError, match="GL_MAX_SHADER_STORAGE_BLOCK_SIZE"):
        r.upload(random_scene(200))


# ---- command line -------------------------------------------------------------------------------------------------


def test_cli_render_glsl(gl, tmp_path):
    npy = tmp_path / "g.npy"
    args = [str(gb.DEFAULT_SCENE), "--width", "64", "--height", "48", "--mode", "gaussian_blending", "--out"]
    assert main(["render", *args, str(npy), "--backend", "glsl"]) == 0
    scene = gb.load(gb.DEFAULT_SCENE)
    ref = gb.render(
        scene, gb.orbit_camera(scene, width=64, height=48), "gaussian_blending+fast"
    ).rgb  # render's default
    assert np.abs(np.load(npy) - ref).max() < MAX_TOL


def test_cli_bench_cpu_and_glsl(gl, tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert (
        main(
            [
                "bench",
                str(gb.DEFAULT_SCENE),
                "--backends",
                "cpu,glsl",
                "--modes",
                "scalar,gaussian_blending",
                "--views",
                "1",
                "--repeat",
                "1",
                "--size",
                "64x48",
                "--rates",
                "1,1/2",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    doc = json.loads(out.read_text())
    rows = [r for r in doc["speed"] if r["backend"] == "glsl"]
    assert len(rows) == 4 and all(r["visible"] > 0 for r in rows)
    assert "OpenGL" in doc["machine"]["glsl_backend"]
    assert any(r["backend"] == "glsl" and r["ratio"] == "gaussian_blending / scalar" for r in doc["ratios"])


def test_headless_renderer_survives_another_current_context(gl, bundled_scene):
    """Another context made current in this thread (an app window, say) must not receive the renderer's work."""
    import moderngl

    cam = gb.orbit_camera(bundled_scene, width=48, height=40)
    r = GlslRenderer()
    r.upload(bundled_scene)
    other = moderngl.create_context(standalone=True, backend="egl")  # current from here on
    try:
        frame = r.render(cam, RenderSettings())
        other.clear(0.0, 0.0, 0.0)  # the other context still works
    finally:
        other.release()
    ref = gb.get_renderer(bundled_scene, "cpu").render(cam, RenderSettings())
    assert frame.stats.visible == ref.stats.visible > 0
    assert np.abs(frame.rgb - ref.rgb).max() < MAX_TOL
