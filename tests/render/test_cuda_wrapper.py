"""The CUDA backend's Python wrapper without a GPU, on a stand-in native renderer (cuda_fakes): state after failed
uploads, release freeing the device buffers, a failed device (BackendFailed, usable(), the CLI's one line; the
registry's replacement is tested by tests/render/test_contract.py), the texture registrations (a GL name reused by
another texture), the GL finish after interop, which GL device interop accepts, and what a level-of-detail cut
drawn in place uploads."""

from __future__ import annotations

import numpy as np
import pytest
from cuda_fakes import TIMEOUT, FakeNative, fake_renderer
from helpers import front_camera, random_scene

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.core.errors import BackendFailed, RenderError
from gbviewer.render.cuda import interop_status
from gbviewer.render.cuda_textures import TextureRegistrations
from gbviewer.render.prepare import prepare


def test_cuda_wrapper_failed_upload_is_retried():
    """After an upload fails (out of device memory) the wrapper does not think the scene is on the device: the next
    frame uploads it again; the same for duplex cells."""
    scene = random_scene(30, seed=4)
    fake = FakeNative(fail={"upload", "upload_cells"})
    r = fake_renderer(fake)
    with pytest.raises(RenderError, match="out of device memory"):
        r.upload(scene)
    assert r._uploaded is None and r.usable() == (True, "")  # out of memory: still usable
    cam, duplex = front_camera(), gb.RenderSettings("duplex")
    with pytest.raises(RenderError, match="out of device memory"):
        r._sync(prepare(r._scene, cam, duplex, "cuda"))  # the scene goes up again; its cells fail
    assert fake.calls == ["upload", "upload", "upload_cells"] and r._uploaded is scene and r._cells is None
    r._sync(prepare(r._scene, cam, duplex, "cuda"))
    r._sync(prepare(r._scene, cam, duplex, "cuda"))
    assert fake.calls == ["upload", "upload", "upload_cells", "upload_cells"]


def test_release_frees_the_device_buffers():
    """release() frees the native renderer's device buffers (it only forgot the scene, holding several GB at 6 M
    splats, while the CPU and GLSL backends free theirs); the next frame uploads the scene again. After a device
    failure it forgets the scene without calling the failed device, and raises nothing."""
    scene = random_scene(20, seed=2)
    fake = FakeNative()
    r = fake_renderer(fake)
    r.upload(scene)
    r.release()
    r.release()
    assert fake.calls == ["upload", "release_buffers", "release_buffers"] and r._uploaded is None
    with pytest.raises(RenderError, match="upload"):
        r.render(front_camera(), gb.RenderSettings())
    r.upload(scene)
    r.render(front_camera(), gb.RenderSettings())
    assert fake.calls[-2:] == ["upload", "render"]
    broken = FakeNative(device_fails={"render"})
    r = fake_renderer(broken)
    r.upload(scene)
    with pytest.raises(BackendFailed):
        r.render(front_camera(), gb.RenderSettings())
    r.release()
    assert broken.calls == ["upload", "render"] and r._scene is None


def test_cuda_wrapper_without_scene():
    with pytest.raises(RenderError, match="upload"):
        fake_renderer(FakeNative()).render(front_camera(), gb.RenderSettings())


@pytest.mark.parametrize("method", ["render", "upload"])
def test_failed_device_makes_the_renderer_unusable(method):
    """A DeviceFailed from the native renderer is BackendFailed (a RenderError) with its one-line reason; from then
    on usable() says so and every call raises it again without reaching the device."""
    fake = FakeNative(device_fails={method})
    r = fake_renderer(fake)
    scene = random_scene(20, seed=1)
    stopped = "^cuda backend stopped working: CUDA device 0 failed: .*timed out"
    with pytest.raises(BackendFailed, match=stopped) as info:
        r.upload(scene)
        r.render(front_camera(), gb.RenderSettings())
    assert isinstance(info.value, RenderError) and "\n" not in str(info.value)
    assert r.usable() == (False, TIMEOUT)
    calls = list(fake.calls)
    for again in (lambda: r.render(front_camera(), gb.RenderSettings()), lambda: r.upload(scene)):
        with pytest.raises(BackendFailed, match="timed out"):
            again()
    assert fake.calls == calls
    r.release_texture(3)  # the viewer still deletes its textures: the native side forgets the registration
    assert fake.calls == [*calls, "release 3"]


def test_cli_says_a_failed_device_in_one_line(monkeypatch, tmp_path, capsys):
    """`gbviewer render` on a renderer whose device fails: exit status 2, one line on stderr, no image written."""
    broken = fake_renderer(FakeNative(device_fails={"render"}))
    monkeypatch.setattr("gbviewer.cli.render.get_renderer", lambda scene, backend: (broken.upload(scene), broken)[1])
    out = tmp_path / "a.png"
    assert (
        main(
            ["render", str(gb.DEFAULT_SCENE), "--width", "32", "--height", "24", "--backend", "cpu", "--out", str(out)]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("gbviewer: error: cuda backend stopped working: CUDA device 0 failed:"), err
    assert not out.exists() and not list(tmp_path.iterdir())


class Ctx:
    def __init__(self):
        self.finished = 0

    def finish(self):
        self.finished += 1


class Texture:
    components, dtype = 4, "f4"

    def __init__(self, glo, size=(32, 24), ctx=None):
        self.glo, self.size, self.ctx = glo, size, ctx or Ctx()


def test_a_reused_texture_name_drops_the_stale_registration():
    """A GL name that comes back as another texture object (deleted, then reused by GL) has its registration
    dropped before the render registers the new texture; the same object keeps its registration; release_texture
    drops it."""
    fake = FakeNative()
    r = fake_renderer(fake)
    scene = random_scene(20, seed=3)
    r.upload(scene)
    cam, settings = front_camera(32, 24), gb.RenderSettings()
    first, reused = Texture(7), Texture(7)
    r.render_to_texture(first, cam, settings)
    r.render_to_texture(first, cam, settings)
    r.render_to_texture(reused, cam, settings)
    r.render_to_texture(Texture(8), cam, settings)
    r.release_texture(7)
    assert fake.calls == [
        "upload",
        "render_to_gl_texture",
        "render_to_gl_texture",
        "release 7",
        "render_to_gl_texture",
        "render_to_gl_texture",
        "release 7",
    ]
    assert len(r._textures) == 1


def test_registrations_bookkeeping():
    released = []
    regs = TextureRegistrations(released.append)
    a, b = Texture(3), Texture(3)
    assert regs.claim(a) == 3 and regs.claim(a) == 3 and released == []
    assert regs.claim(b) == 3 and released == [3]
    regs.forget(3)
    assert released == [3, 3] and len(regs) == 0


def test_gl_finish_after_the_cuda_writes():
    """render_to_texture finishes the texture's GL context after the native copy (the unmap reaches GL before the
    UI context samples the texture), and not when the render fails."""
    fake = FakeNative()
    r = fake_renderer(fake)
    r.upload(random_scene(20, seed=5))
    tex = Texture(9)
    r.render_to_texture(tex, front_camera(32, 24), gb.RenderSettings())
    assert tex.ctx.finished == 1
    fake.device_fails.add("render_to_gl_texture")
    with pytest.raises(BackendFailed):
        r.render_to_texture(tex, front_camera(32, 24), gb.RenderSettings())
    assert tex.ctx.finished == 1


@pytest.mark.parametrize(
    "gl, device, ok, words",
    [
        ([], 0, False, "does not run on a CUDA device"),
        ([0], 0, True, ""),
        ([1], 0, False, "runs on CUDA device 1, the cuda renderer on device 0: frames are copied"),
        ([0, 1], 1, True, ""),
    ],
)
def test_interop_only_on_the_renderers_device(gl, device, ok, words):
    """The GPU display path is taken only where the GL context runs on the device of the renderer that writes it
    (else the viewer copies frames instead of failing every one)."""
    got, why = interop_status(gl, device)
    assert got is ok and words in why and (ok or why)


def test_fake_render_returns_a_frame():
    """The stand-in's render goes through the wrapper like the module's (the fakes above are faithful enough)."""
    r = fake_renderer(FakeNative())
    r.upload(random_scene(10, seed=6))
    f = r.render(front_camera(16, 12), gb.RenderSettings())
    assert f.rgb.shape == (12, 16, 3) and f.stats.visible == 5 and np.all(f.alpha == 0)


def test_a_level_of_detail_cut_goes_up_when_it_changes():
    """The wrapper draws a level-of-detail cut in place: the hierarchy's nodes go up once after the scene, the cut's
    rows (the scene's splats, then interior node q as row N + q, in the gathered Scene's order) only when they change,
    so a still camera and its other panes upload nothing; a frame without level of detail draws the scene's rows;
    duplex renders the gathered cut's Scene (its cells are of that Scene's splats)."""
    scene = random_scene(2000, seed=8, spread=3.0)
    fake = FakeNative()
    r = fake_renderer(fake)
    r.upload(scene)
    near, far = front_camera(f=20.0), front_camera(f=5.0)
    lod2 = gb.RenderSettings.parse("gaussian_blending+lod:2")
    frame = r.render(near, lod2)
    r.render(near, lod2)
    r.render(near, gb.RenderSettings.parse("scalar+lod:2"))
    assert fake.calls == ["upload", "upload_lod", "upload_cut"] + ["render cut"] * 3 and r.uploads == 3
    tree = gb.lod.hierarchy_for(scene)
    for cam in (near, far):
        c = gb.lod.cut(tree, cam, 2.0)
        assert r.render(cam, lod2).stats.lod_splats == c.num_drawn
        rows, weights = fake.cut
        assert len(c.nodes) and np.array_equal(rows, np.concatenate([c.leaves, c.nodes + scene.num_splats]))
        assert np.array_equal(weights, np.concatenate([c.leaf_weights, c.node_weights]))
    assert frame.stats.lod_splats != c.num_drawn  # the far camera's cut is another one, which went up
    assert fake.calls[-3:] == ["render cut", "upload_cut", "render cut"]
    r.render(far, gb.RenderSettings())
    r.render(far, gb.RenderSettings.parse("duplex+lod:2"))
    assert fake.calls[-4:] == ["render", "upload", "upload_cells", "render"] and r.uploads == 6
