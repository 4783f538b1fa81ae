"""`render_to_texture`: the GPU backends render into a caller's RGBA32F texture (the viewer's GPU display path) and
return only the stats. The texture must hold exactly what `render` returns (rgb, alpha), and the stats must equal
`render`'s (the evaluation counts summed on the GPU). glsl runs on llvmpipe here; cuda needs a GPU whose OpenGL
context CUDA can write (CUDA-GL interop) and skips, saying why, elsewhere."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.core.errors import RenderError
from gbviewer.render import CudaRenderer, RenderSettings

SPECS = ["scalar", "gaussian_blending", "gaussian_blending+fast", "analytic:2", "wsr", "duplex"]
SAME_STATS = ("visible", "sort_length", "pairs", "evaluations", "evals_per_pixel", "backend", "mode", "precision")


@pytest.fixture(scope="module")
def glsl():
    from gbviewer.render.glsl import GlslRenderer

    ok, why = GlslRenderer.available()
    if not ok:
        skip_or_fail(why)
    return GlslRenderer


def texture_image(tex) -> np.ndarray:
    w, h = tex.size
    return np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)


def check_same(tex, stats, frame) -> None:
    img = texture_image(tex)
    np.testing.assert_array_equal(img[:, :, :3], frame.rgb)
    np.testing.assert_array_equal(img[:, :, 3], frame.alpha)
    for key in SAME_STATS:
        assert getattr(stats, key) == getattr(frame.stats, key), key
    assert stats.evaluations == int(frame.debug["evals"].sum(dtype=np.int64)) > 0


@pytest.mark.parametrize("spec", SPECS)
def test_glsl_texture_holds_the_frame_and_the_stats_match(glsl, bundled_scene, spec):
    r = glsl()
    r.upload(bundled_scene)
    # odd sizes: partial tiles; 5917 pixels: six 1024-pixel blocks of evaluation sums, the last one partial
    cam = gb.orbit_camera(bundled_scene, 30, 10, width=97, height=61)
    settings = RenderSettings.parse(spec)
    tex = r.ctx.texture((97, 61), 4, dtype="f4")
    stats = r.render_to_texture(tex, cam, settings)
    check_same(tex, stats, r.render(cam, settings))
    cam2 = gb.orbit_camera(bundled_scene, 70, 25, width=97, height=61)  # the same texture again, another view
    check_same(tex, r.render_to_texture(tex, cam2, settings), r.render(cam2, settings))
    tex.release()
    r.release()


@pytest.mark.parametrize("size, components, dtype", [((96, 61), 4, "f4"), ((97, 61), 3, "f4"), ((97, 61), 4, "f1")])
def test_glsl_refuses_a_texture_the_frame_does_not_fit(glsl, bundled_scene, size, components, dtype):
    r = glsl()
    r.upload(bundled_scene)
    tex = r.ctx.texture(size, components, dtype=dtype)
    cam = gb.orbit_camera(bundled_scene, width=97, height=61)
    with pytest.raises(RenderError, match=r"render_to_texture: expected an RGBA32F .* of 97x61"):
        r.render_to_texture(tex, cam, RenderSettings())
    tex.release()
    r.release()


def test_glsl_render_to_texture_can_be_cancelled(glsl, bundled_scene):
    import threading

    r = glsl()
    r.upload(bundled_scene)
    cancel = threading.Event()
    cancel.set()
    tex = r.ctx.texture((64, 48), 4, dtype="f4")
    with pytest.raises(gb.RenderCancelled):
        r.render_to_texture(tex, gb.orbit_camera(bundled_scene, width=64, height=48), RenderSettings(), cancel=cancel)
    tex.release()
    r.release()


# ---- cuda (GPU only) ----------------------------------------------------------------------------------------------


def cuda_gl_context():
    """A GL context CUDA can write, current in this thread (the process's headless EGL one); skips where none."""
    ok, why = CudaRenderer.available()
    if not ok:
        pytest.skip(f"no CUDA device here: {why}")
    from gbviewer.render.glsl import standalone_context

    try:
        ctx = standalone_context()
    except gb.BackendUnavailable as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    ctx.__enter__()  # current in this thread (stays so)
    ok, why = CudaRenderer.gl_interop()
    if not ok:
        pytest.skip(f"no CUDA-GL interop with {ctx.info.get('GL_RENDERER', '?')}: {why}")
    return ctx


@pytest.mark.parametrize("spec", SPECS)
def test_cuda_texture_holds_the_frame_and_the_stats_match(bundled_scene, spec):
    ctx = cuda_gl_context()
    r = CudaRenderer()
    r.upload(bundled_scene)
    cam = gb.orbit_camera(bundled_scene, 30, 10, width=97, height=61)
    settings = RenderSettings.parse(spec)
    tex = ctx.texture((97, 61), 4, dtype="f4")
    try:
        for _ in range(2):  # the second frame reuses the texture's CUDA registration
            check_same(tex, r.render_to_texture(tex, cam, settings), r.render(cam, settings))
        wrong = ctx.texture((96, 61), 4, dtype="f4")
        with pytest.raises(RenderError, match="expected an RGBA32F"):
            r.render_to_texture(wrong, cam, settings)
        wrong.release()
    finally:
        r.release_texture(tex.glo)
        r.release_texture(tex.glo)  # a second release is a no-op
        tex.release()


@pytest.mark.parametrize("spec", ["scalar:2", "duplex"])
def test_cuda_wrapper_passes_the_texture_and_the_render_arguments(bundled_scene, spec):
    """Without a GPU: the wrapper's call of the binding, on a stand-in renderer whose render_to_gl_texture checks
    its arguments with the real module's checks (those of render, which also takes want_window)."""
    _native_cuda = pytest.importorskip("gbviewer._native_cuda", reason="the CUDA module is not built (no nvcc)")
    from cuda_fakes import FakeNative, fake_renderer

    class Native(FakeNative):
        def render_to_gl_texture(self, texture, *args, view_filter=None, seed=0, frame=0, fast=False, cut=False):
            assert texture == 7 and len(args) == (19 if spec == "duplex" else 15) and not cut  # + the oit globals
            _native_cuda.check_render_args(*args, view_filter=view_filter, seed=seed, frame=frame, fast=fast)
            return super().render_to_gl_texture(
                texture, *args, view_filter=view_filter, seed=seed, frame=frame, fast=fast
            )

    class Texture:
        glo, size, components, dtype = 7, (32, 24), 4, "f4"
        ctx = type("Ctx", (), {"finish": lambda self: None})()

    native = Native()
    r = fake_renderer(native)
    r.upload(bundled_scene)
    settings = RenderSettings.parse(spec)
    stats = r.render_to_texture(Texture(), gb.orbit_camera(bundled_scene, width=32, height=24), settings)
    assert native.calls[-1] == "render_to_gl_texture"
    assert (stats.backend, stats.visible, stats.evaluations, stats.evals_per_pixel) == ("cuda", 5, 96, 96 / (32 * 24))
    assert (stats.cells_visible is not None) == (spec == "duplex")
