"""The viewer's backend "auto" (its default): decided by the render thread from its own probes, shown with the
reason, overridable; settings of version 1, which saved cpu as their default, pick again."""

from __future__ import annotations

import json

import pytest

import gbviewer as gb
from gbviewer.app.settings import AppSettings, load_settings
from gbviewer.app.threads.worker import RenderWorker
from gbviewer.render.choice import BackendChoice, GlProbe, decide


def test_worker_decides_auto_from_what_it_measured():
    w = RenderWorker()
    try:
        assert w.backends_ready.wait(60)
        cuda, glsl = w.backends["cuda"], w.backends["glsl"]
        assert w.auto == decide(cuda, GlProbe.of(w._gl_ctx, glsl[1]))
        assert w.backend_status("auto") == (True, str(w.auto))
        assert w.backend_for("auto") == (w.auto.name if w.backend_status(w.auto.name)[0] else "cpu")
        renderer = w._gl_ctx.info["GL_RENDERER"] if w._gl_ctx is not None else ""
        if not cuda[0] and "llvmpipe" in renderer:  # this machine: no GPU, Mesa's software OpenGL
            assert w.backend_for("auto") == "cpu" and "llvmpipe" in w.auto.reason and "CUDA" in w.auto.reason
        w.auto = BackendChoice("cuda", "pretend")  # a pick that cannot run here falls back to cpu
        w.backends["cuda"] = (False, "no device")
        assert w.backend_for("auto") == "cpu" and w.backend_for("cpu") == "cpu"
    finally:
        w.stop()


@pytest.mark.parametrize(
    "doc, backend",
    [
        ({"version": 1, "backend": "cpu"}, "auto"),  # cpu was version 1's default, saved whatever the machine had
        ({"version": 1, "backend": "glsl"}, "glsl"),
        ({"version": 2, "backend": "cpu"}, "cpu"),
        ({"version": 2, "backend": "vulkan"}, "auto"),
        ({}, "auto"),
    ],
)
def test_settings_backend(tmp_path, doc, backend):
    path = tmp_path / "settings.json"
    path.write_text(json.dumps(doc))
    assert load_settings(path)[0].backend == backend
    assert json.loads(AppSettings().to_json())["version"] == 2 and AppSettings().backend == "auto"


@pytest.mark.display
def test_viewer_renders_on_the_auto_pick_and_an_override(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.window import ViewerApp

    app = ViewerApp(None, size=(800, 500), backend=None)
    try:
        assert app.wait_rendered(180) and app.state.settings.backend == "auto"
        picked = app.worker.backend_for("auto")
        assert {p.parts["a"].job.backend for p in app.state.visible} == {picked}
    finally:
        app.close()
    app = ViewerApp(gb.DEFAULT_SCENE, size=(800, 500), backend="cpu")  # `gbviewer --backend cpu`
    try:
        assert app.wait_rendered(180) and app.state.settings.backend == "cpu"
        assert {p.parts["a"].job.backend for p in app.state.visible} == {"cpu"}
    finally:
        app.close()
