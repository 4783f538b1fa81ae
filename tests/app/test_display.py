"""The display paths (gbviewer/app/frames/display.py) in the real window under Xvfb (Mesa llvmpipe): the GPU display
path, forced there with GBVIEWER_DISPLAY_PATH=gpu, draws glsl frames from the textures they were rendered into, with no
readback, and the same pixels as the CPU render; the copy path (auto on llvmpipe, or forced) is unchanged; the display
textures go when the backend changes and stay bounded while scenes and views change. The cuda display path (CUDA-GL
interop) needs an NVIDIA OpenGL display and skips elsewhere (tests/render/test_render_to_texture.py has its render-level
test)."""

from __future__ import annotations

import shutil
import time

import numpy as np
import pytest
from helpers import skip_or_fail
from window_helpers import LABEL_BAND, agree, expected_pane, pane_pixels, shot, wait

import gbviewer as gb
from gbviewer.app.frames.display import MAX_FREE, GpuFrame, is_software, requested_path
from gbviewer.app.frames.views import decode_png16
from gbviewer.render import Frame

pytestmark = pytest.mark.display
GLSL_VS_CPU = 5e-3  # as test_window's glsl pane check: max |glsl - cpu| on the bundled scene


def open_app(monkeypatch, tmp_path, path: str):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.setenv("GBVIEWER_DISPLAY_PATH", path)
    from gbviewer.app.window import ViewerApp

    app = ViewerApp(None, size=(1040, 700), persist=False)
    app.state.settings.show_info = False
    app.worker.backends_ready.wait(60)
    return app


@pytest.fixture
def gpu_app(xvfb, tmp_path, monkeypatch):
    app = open_app(monkeypatch, tmp_path, "gpu")
    ok, why = app.worker.backend_status("glsl")
    if not ok:
        app.close()
        skip_or_fail(f"glsl backend unavailable: {why}")
    yield app
    app.close()


def parts(app):
    return [(p, part, p.parts[part]) for p in app.state.visible for part in app.state.parts(p.index)]


def settle(app, until, timeout: float = 30.0) -> bool:
    """Step the window until `until()` (textures come back to the render thread after the UI drops their frames)."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        app.step()
        if until():
            return True
        time.sleep(0.02)
    return False


def test_requests_and_software_renderers():
    assert requested_path({}) == ("auto", "")
    assert requested_path({"GBVIEWER_DISPLAY_PATH": " GPU "}) == ("gpu", "")
    path, warning = requested_path({"GBVIEWER_DISPLAY_PATH": "fast"})
    assert path == "auto" and "GBVIEWER_DISPLAY_PATH='fast'" in warning and "auto, gpu, copy" in warning
    assert is_software("llvmpipe (LLVM 15.0.6, 256 bits)") and is_software("Software Rasterizer")
    assert not is_software("NVIDIA H100/PCIe/SSE2") and not is_software("AMD Radeon RX 7900 XTX (radeonsi)")


def test_gpu_display_path_draws_glsl_frames_from_their_textures(gpu_app, tmp_path):
    app = gpu_app
    assert app.worker.display_path("glsl")[0] == "gpu" and app.worker.display_path("cpu")[0] == "copy"
    app.state.settings.backend = "glsl"
    app.state.set_pane_count(2)
    app.state.settings.layout = "row"
    app.state.set_pane(0, mode="scalar", supersample=1, split=True, split_mode="analytic", split_pos=0.5)
    app.state.set_pane(1, mode="gaussian_blending", supersample=2, split=False)
    app.state.set_rate(1 / 4)
    readbacks = GpuFrame.readbacks
    wait(app)
    img = shot(app, "viewer-gpu-display")
    for p, part, shown in parts(app):
        assert isinstance(shown.frame, GpuFrame) and not shown.frame.on_cpu, (p.name, part)
        assert shown.job.display == "gpu" and shown.image is None and shown.frame.stats.backend == "glsl"
        assert shown.texture.glo == shown.frame.glo
    assert GpuFrame.readbacks == readbacks, "the display path read pixels back"
    # the window shows the CPU render's pixels (nearest-upscaled, within one level)
    half = app.state.panes[0].rect.w // 2
    split = pane_pixels(img, app.state.panes[0].rect)[LABEL_BAND:]
    assert agree(split[:, : half - 6], expected_pane(app, 0, "a")[LABEL_BAND:, : half - 6]) > 0.995
    assert agree(split[:, half + 6 :], expected_pane(app, 0, "b")[LABEL_BAND:, half + 6 :]) > 0.995
    got = pane_pixels(img, app.state.panes[1].rect)[LABEL_BAND:]
    assert agree(got, expected_pane(app, 1)[LABEL_BAND:]) > 0.995 and got.std() > 10

    # pixels on the CPU only when a feature asks: a pane screenshot reads its frame back, once
    shown = app.state.panes[1].parts["a"]
    path = app.screenshot_pane(1, tmp_path / "pane.png")
    assert GpuFrame.readbacks == readbacks + 1 and shown.frame.on_cpu
    data = decode_png16(path.read_bytes())
    assert np.abs(data / 65535 - np.clip(shown.frame.rgb, 0, 1)).max() < 1e-4 and GpuFrame.readbacks == readbacks + 1
    ref = gb.render(app.state.scene, shown.job.camera, shown.job.settings.mode, shown.job.settings.supersample)
    assert np.abs(shown.frame.rgb - ref.rgb).max() < GLSL_VS_CPU
    assert np.abs(shown.frame.alpha - ref.alpha).max() < GLSL_VS_CPU

    # a debug view needs planes the texture does not hold: that pane renders on the copy path, and back
    app.state.set_pane(1, view="evals")
    wait(app)
    assert type(shown.frame) is Frame and shown.job.display == "copy" and shown.view == "evals"
    assert shown.image is not None and shown.image.std() > 1 and shown.legend
    app.state.set_pane(1, view="color")
    wait(app)
    assert isinstance(shown.frame, GpuFrame) and shown.view == "color"


@pytest.mark.parametrize("request_", ["copy", "auto"])
def test_copy_path_on_llvmpipe_unless_forced(xvfb, tmp_path, monkeypatch, request_):
    app = open_app(monkeypatch, tmp_path, request_)
    try:
        if not is_software(app.gl_renderer):
            pytest.skip(f"auto takes the GPU path on {app.gl_renderer}")
        path, why = app.worker.display_path("glsl")
        assert path == "copy" and app.shared.window is None
        assert ("GBVIEWER_DISPLAY_PATH=copy" if request_ == "copy" else "software") in why
        app.state.set_pane_count(1)
        app.state.set_rate(1 / 8)
        if app.worker.backend_status("glsl")[0]:
            app.state.settings.backend = "glsl"
        wait(app)
        shown = app.state.panes[0].parts["a"]
        assert type(shown.frame) is Frame and shown.job.display == "copy" and shown.image is not None
        img = shot(app, f"viewer-copy-display-{request_}")
        assert agree(pane_pixels(img, app.state.panes[0].rect)[LABEL_BAND:], expected_pane(app, 0)[LABEL_BAND:]) > 0.995
        assert app.worker.textures.live == 0
    finally:
        app.close()


def test_display_textures_are_bounded_and_released_with_the_backend(gpu_app, tmp_path):
    from soak_viewer import gl_object_counts

    app = gpu_app
    app.state.set_pane_count(2)
    app.state.set_pane(0, split=True)
    app.state.set_rate(1 / 8)
    wait(app)
    on_cpu = gl_object_counts()  # the copy path's textures: one per pane part
    app.state.settings.backend = "glsl"
    shown_parts = len(parts(app))
    for k in range(3):
        copy = tmp_path / f"scene{k}.ply"  # a new Scene object each time
        shutil.copy(gb.DEFAULT_SCENE, copy)
        app.state.open(copy)
        wait(app)
        app.state.controller.orbit(15, 5)  # previews at other sizes, then the final frames
        app.state.moved()
        app.run_frames(3)
        wait(app)
        assert all(isinstance(shown.frame, GpuFrame) for _, _, shown in parts(app))
        assert settle(app, lambda: app.worker.textures.live <= shown_parts + MAX_FREE), app.worker.textures.live
    counts = gl_object_counts()
    assert counts["texture"] <= on_cpu["texture"] + shown_parts + MAX_FREE
    app.state.settings.backend = "cpu"  # the copy path: every display texture goes once no frame shows it
    wait(app)
    assert settle(app, lambda: app.worker.textures.live == 0), app.worker.textures.live
    assert gl_object_counts()["texture"] == on_cpu["texture"]


def test_cuda_display_path_where_the_window_runs_on_a_cuda_device(gpu_app):
    app = gpu_app
    if not app.worker.backend_status("cuda")[0]:
        pytest.skip(f"no CUDA device: {app.worker.backend_status('cuda')[1]}")
    path, why = app.worker.display_path("cuda")
    if path != "gpu":
        pytest.skip(f"no CUDA-GL interop with this display ({app.gl_renderer}): {why}")
    app.state.settings.backend = "cuda"
    app.state.set_pane_count(1)
    app.state.set_rate(1 / 4)
    readbacks = GpuFrame.readbacks
    wait(app)
    img = shot(app, "viewer-cuda-display")
    shown = app.state.panes[0].parts["a"]
    assert isinstance(shown.frame, GpuFrame) and shown.frame.stats.backend == "cuda"
    assert GpuFrame.readbacks == readbacks
    assert agree(pane_pixels(img, app.state.panes[0].rect)[LABEL_BAND:], expected_pane(app, 0)[LABEL_BAND:]) > 0.99
