"""`backend="auto"`: CUDA where usable, else GLSL on a hardware OpenGL 4.3 driver, else the CPU; the reason says why,
the decision is made once per process, explicit backends win, and the probes never raise."""

from __future__ import annotations

import threading
import time

import pytest
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.core.errors import RenderError
from gbviewer.render import choice, registry
from gbviewer.render.choice import BackendChoice, GlProbe, decide

LLVMPIPE = GlProbe("llvmpipe (LLVM 15.0.6, 256 bits)", 450)
RTX = GlProbe("NVIDIA GeForce RTX 4090/PCIe/SSE2", 460)


@pytest.fixture(autouse=True)
def fresh_choice():
    choice.forget_choice()
    yield
    choice.forget_choice()


def fake_probes(monkeypatch, cuda: tuple[bool, str], gl: GlProbe) -> dict[str, int]:
    calls = {"cuda": 0, "gl": 0}

    def probe_cuda():
        calls["cuda"] += 1
        return cuda

    def probe_gl():
        calls["gl"] += 1
        return gl

    monkeypatch.setattr(choice, "probe_cuda", probe_cuda)
    monkeypatch.setattr(choice, "probe_gl", probe_gl)
    return calls


def test_this_machine_gets_what_its_probes_say():
    """Here (no GPU, Mesa llvmpipe): the CPU, and the reason names both the CUDA failure and the software GL."""
    cuda, gl = choice.probe_cuda(), choice.probe_gl()
    picked = gb.choose_backend()
    assert isinstance(picked, BackendChoice) and picked == decide(cuda, None if cuda[0] else gl)
    if not cuda[0] and (gl.error or gl.software):
        assert picked.name == "cpu" and "CUDA unavailable" in picked.reason
        assert (
            (gl.renderer in picked.reason and "software rasterizer" in picked.reason)
            if gl.software
            else gl.error in picked.reason
        )
    assert str(picked) == f"{picked.name} (auto: {picked.reason})"
    assert registry.resolve_backend("auto") == picked.name


@pytest.mark.parametrize(
    "cuda, gl, name, words",
    [
        ((True, ""), LLVMPIPE, "cuda", ["CUDA device is usable"]),
        ((False, "no CUDA device found"), RTX, "glsl", ["no CUDA device found", "RTX 4090", "4.6"]),
        ((False, "no CUDA device found"), LLVMPIPE, "cpu", ["no CUDA device found", "llvmpipe", "software"]),
        ((False, "not built"), GlProbe("softpipe", 450), "cpu", ["not built", "softpipe", "software"]),
        ((False, "not built"), GlProbe("Apple M1", 410), "cpu", ["4.1 on Apple M1", "compute shaders"]),
        (
            (False, "not built"),
            GlProbe(error="no OpenGL 4.3 context: EGL_NOT_INITIALIZED"),
            "cpu",
            ["not built", "EGL_NOT_INITIALIZED"],
        ),
    ],
)
def test_choice_from_probes(monkeypatch, cuda, gl, name, words):
    calls = fake_probes(monkeypatch, cuda, gl)
    picked = gb.choose_backend()
    assert picked.name == name and all(w in picked.reason for w in words), picked
    assert calls == {"cuda": 1, "gl": 0 if cuda[0] else 1}  # no OpenGL context where CUDA is usable
    assert gb.choose_backend() is picked and calls["cuda"] == 1  # once per process
    choice.forget_choice()
    gb.choose_backend()
    assert calls["cuda"] == 2


def test_explicit_backends_win_over_auto(monkeypatch, bundled_scene):
    fake_probes(monkeypatch, (False, "no CUDA device found"), RTX)
    assert registry.resolve_backend("auto") == "glsl"
    assert registry.resolve_backend("cpu") == "cpu" and gb.get_renderer(bundled_scene, "cpu").name == "cpu"
    choice.forget_choice()
    fake_probes(monkeypatch, (False, "no CUDA device found"), LLVMPIPE)
    assert gb.get_renderer(bundled_scene, "auto").name == "cpu"
    cam = gb.orbit_camera(bundled_scene, width=32, height=24)
    assert gb.render(bundled_scene, cam, backend="auto").stats.total_ms >= 0
    with pytest.raises(RenderError, match="auto, cpu, cuda, glsl"):
        registry.resolve_backend("vulkan")


def test_probes_never_raise(monkeypatch):
    def broken():
        raise RuntimeError("driver exploded")

    monkeypatch.setattr(choice.CudaRenderer, "available", classmethod(lambda cls: broken()))
    assert choice.probe_cuda() == (False, "RuntimeError: driver exploded")
    monkeypatch.setattr(choice, "create_context", broken)
    assert choice.probe_gl().error == "no OpenGL context: RuntimeError: driver exploded"
    picked = gb.choose_backend()
    assert picked.name == "cpu" and "driver exploded" in picked.reason


def test_macos_gets_the_cpu_backend_saying_why(monkeypatch):
    """macOS's OpenGL ends at 4.1 (no compute shaders): auto says so and picks the CPU (CUDA aside)."""
    monkeypatch.setattr(choice.CudaRenderer, "available", classmethod(lambda cls: (False, "no CUDA on macOS")))
    monkeypatch.setattr("sys.platform", "darwin")
    assert "macOS has no OpenGL 4.3" in choice.probe_gl().error
    picked = gb.choose_backend()
    assert picked.name == "cpu" and "macOS has no OpenGL 4.3" in picked.reason


def test_a_hanging_gl_driver_counts_as_none(monkeypatch):
    release = threading.Event()

    def hang():
        release.wait(10)
        raise RuntimeError("too late")

    monkeypatch.setattr(choice, "create_context", hang)
    monkeypatch.setattr(choice, "GL_PROBE_TIMEOUT_S", 0.05)
    t0 = time.perf_counter()
    probe = choice.probe_gl()
    release.set()
    assert "within 0.05 s" in probe.error and probe.renderer == ""
    assert time.perf_counter() - t0 < 10  # it did not wait for the driver


@pytest.mark.gl
def test_probe_gl_leaves_the_callers_context_alone():
    """The probe's context is made current and released in its own thread: the one current in the calling thread
    (here the glsl backend's process-wide one) still works (made and released here, the probe would leave no context
    current)."""
    from gbviewer.render.glsl.context import standalone_context

    try:
        ctx = standalone_context()
    except gb.BackendUnavailable as exc:
        skip_or_fail(str(exc))
    ctx.__enter__()  # current in this thread, as the glsl backend leaves it
    probe = choice.probe_gl()
    assert probe.error == "" and probe.version >= 430 and probe.renderer
    buf = ctx.buffer(b"\x01\x02\x03\x04")
    assert buf.read() == b"\x01\x02\x03\x04"
    buf.release()


def test_auto_passes_over_a_backend_that_stopped_working():
    """A backend that raised BackendFailed is passed over: auto picks what it would pick without it."""
    gl = GlProbe("NVIDIA GeForce RTX 4090/PCIe/SSE2", 460)
    assert decide((True, ""), gl).name == "cuda"
    lost = decide((True, ""), gl, {"cuda": "an illegal memory access"})
    assert lost.name == "glsl" and "stopped working: an illegal memory access" in lost.reason
    both = decide((True, ""), gl, {"cuda": "lost", "glsl": "context lost"})
    assert both.name == "cpu" and "glsl stopped working (context lost)" in both.reason
