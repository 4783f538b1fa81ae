"""The desktop window: glfw + Dear ImGui (imgui-bundle, its C++ GLFW and OpenGL 3 backends) + moderngl.

`ViewerApp` owns the window; `step()` runs one UI frame and never waits for a render: renders run in
`worker.RenderWorker`'s thread, each pane shows its last finished frame, nearest-upscaled. Tests drive it with
`run_frames(n)` / `wait_rendered()` and the same methods the UI calls.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from imgui_bundle import imgui  # must come before `import glfw`: it points pyGLFW at its own libglfw

import glfw  # noqa: E402  (after imgui_bundle, see above)
import moderngl  # noqa: E402

from .. import DEFAULT_SCENE  # noqa: E402
from ..camera import UP_AXES, load_cameras_json  # noqa: E402
from ..errors import GBViewerError  # noqa: E402
from ..figure import atomic_write, to_uint8  # noqa: E402
from ..render import BACKENDS, Mode, RenderSettings  # noqa: E402
from . import logic  # noqa: E402
from .logic import PANE_NAMES, CameraController, PaneSettings, Rect  # noqa: E402
from .worker import RenderJob, RenderResult, RenderWorker, SceneLoader, VideoJob, video_available  # noqa: E402

PANEL_W = 340
MAX_SAMPLES = 96_000_000  # per render (pixels x supersampling^2): bounds memory and time at x8 with 8x8
VIDEO_PANE_W = 480
PREVIEW_BUDGET_MS = 60.0
MOVING_HOLD_S = 0.25
SCENE_EXTS = (".ply", ".splat", ".spz", ".sog", ".json", ".pth")
KNOWN_BACKENDS = ("cpu", "glsl", "cuda")
DIALOG_PROGRAMS = ("zenity", "kdialog", "qarma", "matedialog", "yad")


def col(r: int, g: int, b: int, a: int = 255) -> int:
    return (a << 24) | (b << 16) | (g << 8) | r


WHITE, BLACK_A, YELLOW, RED, GREY, ACCENT = (col(255, 255, 255), col(0, 0, 0, 170), col(255, 205, 60),
                                               col(255, 90, 80), col(150, 150, 150), col(90, 170, 255))


@dataclass
class Shown:
    """What one pane part (its whole image, or one side of a split) shows: the last finished frame."""

    texture: object = None
    frame: object = None
    job: RenderJob | None = None
    view: str = ""
    legend: str = ""
    image: np.ndarray | None = None  # uint8 (H, W, 3) as uploaded
    error: str = ""


@dataclass
class PaneState:
    index: int
    parts: dict = field(default_factory=lambda: {"a": Shown(), "b": Shown()})
    submitted: dict = field(default_factory=dict)  # part -> key of the last request
    fps: dict = field(default_factory=lambda: {"a": logic.RateMeter(), "b": logic.RateMeter()})
    ms_per_px: dict = field(default_factory=dict)  # part -> measured cost of a full-resolution render
    rect: Rect = Rect(0, 0, 1, 1)
    render_size: tuple[int, int] = (1, 1)  # at the current rate, without a preview drop

    @property
    def name(self) -> str:
        return PANE_NAMES[self.index]


class Blitter:
    """Draws image textures into the window with nearest filtering (Dear ImGui's OpenGL 3 backend binds its own
    linear sampler, so pane images are drawn here, before and after the UI, not through imgui.image)."""

    VS = """#version 330
    uniform vec2 screen;
    in vec2 pos;
    in vec2 uv;
    out vec2 v_uv;
    void main() {
        v_uv = uv;
        gl_Position = vec4(pos.x / screen.x * 2.0 - 1.0, 1.0 - pos.y / screen.y * 2.0, 0.0, 1.0);
    }"""
    FS = """#version 330
    uniform sampler2D tex;
    in vec2 v_uv;
    out vec4 colour;
    void main() { colour = vec4(texture(tex, v_uv).rgb, 1.0); }"""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=self.VS, fragment_shader=self.FS)
        self.vbo = ctx.buffer(reserve=16 * 4)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f 2f", "pos", "uv")])
        self.sampler = ctx.sampler(filter=(moderngl.NEAREST, moderngl.NEAREST), repeat_x=False, repeat_y=False)
        self.quads: list[tuple] = []

    def add(self, texture, x0: float, y0: float, x1: float, y1: float, uv=(0.0, 0.0, 1.0, 1.0)) -> None:
        """Queue a quad (window coordinates) showing the texture's uv rectangle."""
        if texture is not None and x1 > x0 and y1 > y0:
            self.quads.append((texture, x0, y0, x1, y1, uv))

    def flush(self, fb_w: int, fb_h: int, scale: tuple[float, float]) -> None:
        if not self.quads:
            return
        ctx = self.ctx
        ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.screen.use()
        ctx.viewport = (0, 0, fb_w, fb_h)
        ctx.scissor = None
        self.prog["screen"].value = (float(fb_w), float(fb_h))
        self.prog["tex"].value = 0
        sx, sy = scale
        for tex, x0, y0, x1, y1, (u0, v0, u1, v1) in self.quads:
            x0, x1, y0, y1 = x0 * sx, x1 * sx, y0 * sy, y1 * sy
            self.vbo.write(np.array([x0, y0, u0, v0, x1, y0, u1, v0, x0, y1, u0, v1, x1, y1, u1, v1], np.float32))
            tex.use(0)
            self.sampler.use(0)
            self.vao.render(moderngl.TRIANGLE_STRIP)
        self.sampler.clear(0)
        self.quads.clear()

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.prog, self.sampler):
            obj.release()


class ViewerApp:
    """The viewer window. `ViewerApp(path).run()` is `gbviewer [SCENE]`."""

    def __init__(self, scene_path: str | Path | None = None, settings_file: Path | None = None,
                 size: tuple[int, int] | None = None, visible: bool = True, persist: bool = True,
                 cameras: str | Path | None = None) -> None:
        self.settings_file = settings_file
        self.persist = persist
        self.settings, warning = logic.load_settings(settings_file)
        self.messages: list[tuple[float, str, int]] = []
        if warning:
            self.message(warning, RED)
        if size:
            self.settings.window = size
        self.controller = CameraController(fov_y_deg=self.settings.fov_y_deg, up=self.settings.up)
        self.scene = None
        self.scene_path: Path | None = None
        self.cameras: list = []
        self.cameras_path: Path | None = None
        self.cam_index = -1
        self.loader: SceneLoader | None = None
        self.load_error = self.load_error_short = ""
        self.fly = False
        self.show_help = False
        self.last_move = 0.0
        self.frame_count = 0
        self.ui_fps = logic.RateMeter()
        self.panes = [PaneState(i) for i in range(logic.MAX_PANES)]
        self.dragging_split: int | None = None
        self.hover: tuple[int, float, float] | None = None  # pane, u, v under the cursor
        self._pending_screenshot: Path | None = None
        self._file_dialog = None
        self._browser: dict | None = None
        self.closed = False
        self._needs_reset = False
        self.last_screenshot: Path | None = None
        self.video: VideoJob | None = None  # background zoom video, when gbviewer.video provides record_video
        self.video_ok = video_available()[0]
        self.video_frames = 90
        self._init_window(visible)
        self.worker = RenderWorker()
        self._cli_cameras = cameras  # opened once the first scene is in
        self.open(scene_path or DEFAULT_SCENE)

    # ---- window and GL ------------------------------------------------------------------------------------------

    def _init_window(self, visible: bool) -> None:
        glfw.ERROR_REPORTING = "ignore"  # failures are reported below, in one line
        if not glfw.init():
            _, desc = glfw.get_error()
            desc = desc.decode(errors="replace") if isinstance(desc, bytes) else str(desc or "no reason given")
            raise GBViewerError(f"glfw could not initialise ({desc})")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, visible)
        w, h = self.settings.window
        monitor = glfw.get_primary_monitor()
        if monitor:  # fit the screen (a saved size may come from a bigger one)
            _, _, mw, mh = glfw.get_monitor_workarea(monitor)
            if mw > 0 and mh > 0:
                w, h = min(w, mw), min(h, mh)
        self.window = glfw.create_window(w, h, "gbviewer", None, None)
        if not self.window:
            glfw.terminate()
            _, desc = glfw.get_error()
            desc = desc.decode(errors="replace") if isinstance(desc, bytes) else str(desc or "")
            raise GBViewerError(f"glfw could not create an OpenGL 3.3 window ({desc})")
        glfw.make_context_current(self.window)
        glfw.swap_interval(1)
        self.ctx = moderngl.create_context()
        imgui.create_context()
        io = imgui.get_io()
        io.set_ini_filename("")  # the viewer's own settings file keeps what persists
        io.config_flags |= imgui.ConfigFlags_.nav_enable_keyboard.value
        import imgui_bundle

        fonts = Path(imgui_bundle.__file__).resolve().parent / "assets" / "fonts"
        self.font = self.mono = None
        if (fonts / "DroidSans.ttf").exists():
            self.font = io.fonts.add_font_from_file_ttf(str(fonts / "DroidSans.ttf"), 16.0)
        if (fonts / "Inconsolata-Medium.ttf").exists():
            self.mono = io.fonts.add_font_from_file_ttf(str(fonts / "Inconsolata-Medium.ttf"), 15.0)
        self._style()
        addr = ctypes.cast(self.window, ctypes.c_void_p).value
        imgui.backends.glfw_init_for_opengl(addr, True)
        imgui.backends.opengl3_init("#version 330")
        glfw.set_drop_callback(self.window, self._on_drop)
        self.gl_renderer = self.ctx.info.get("GL_RENDERER", "?")
        self.blit_panes = Blitter(self.ctx)  # drawn under the UI
        self.blit_loupe = Blitter(self.ctx)  # drawn over it

    def _style(self) -> None:
        imgui.style_colors_dark()
        st = imgui.get_style()
        st.window_rounding = 0.0
        st.frame_rounding = 3.0
        st.grab_rounding = 3.0
        st.window_border_size = 0.0
        st.item_spacing = imgui.ImVec2(8, 5)
        st.frame_padding = imgui.ImVec2(6, 3)
        st.set_color_(imgui.Col_.window_bg.value, imgui.ImVec4(0.105, 0.11, 0.125, 1.0))
        st.set_color_(imgui.Col_.menu_bar_bg.value, imgui.ImVec4(0.14, 0.15, 0.17, 1.0))
        st.set_color_(imgui.Col_.header.value, imgui.ImVec4(0.20, 0.32, 0.48, 0.75))
        st.set_color_(imgui.Col_.header_hovered.value, imgui.ImVec4(0.26, 0.42, 0.62, 0.85))
        st.set_color_(imgui.Col_.button.value, imgui.ImVec4(0.20, 0.25, 0.32, 1.0))
        st.set_color_(imgui.Col_.button_hovered.value, imgui.ImVec4(0.28, 0.40, 0.56, 1.0))
        st.set_color_(imgui.Col_.frame_bg.value, imgui.ImVec4(0.17, 0.19, 0.23, 1.0))

    def _on_drop(self, _window, paths) -> None:
        for p in paths:
            self.open(p)

    # ---- opening ------------------------------------------------------------------------------------------------

    def open(self, path: str | Path) -> None:
        """Open a scene (in the background) or, for a .json, training cameras."""
        path = Path(path).expanduser()
        if logic.is_cameras_file(path):
            self.open_cameras(path)
            return
        self.load_error = self.load_error_short = ""
        self.loader = SceneLoader(path)

    def open_cameras(self, path: str | Path) -> None:
        try:
            cams = load_cameras_json(path)
        except GBViewerError as exc:
            self.load_error, self.load_error_short = str(exc), ""
            self.message(str(exc), RED)
            return
        self.cameras, self.cameras_path, self.cam_index = cams, Path(path), -1
        self.message(f"{len(cams)} training cameras from {Path(path).name}")
        self.step_camera(1)

    def _poll_loader(self) -> None:
        if self.loader is None or not self.loader.done():
            return
        res = self.loader.poll()
        self.loader = None
        if res.error:
            self.load_error = res.error
            self.load_error_short = res.error.replace(str(res.path), res.path.name)
            self.message(f"could not open {res.path.name}: kept the current scene", RED)
            return
        first = self.scene is None
        self.scene, self.scene_path = res.scene, res.path
        self.load_error = ""
        self.settings.recent = logic.add_recent(self.settings.recent, res.path)
        self.cameras, self.cameras_path, self.cam_index = (res.cameras or []), res.cameras_path, -1
        if res.cameras_error:
            self.message(res.cameras_error, RED)
        for p in self.panes:
            p.parts = {"a": Shown(), "b": Shown()}
            p.submitted.clear()
            p.ms_per_px.clear()
        self._needs_reset = True  # framed once the panes have their size (after this frame's layout)
        glfw.set_window_title(self.window, f"gbviewer - {res.path.name}")
        self.message(f"opened {res.path.name}: {res.scene.num_splats:,} splats in {res.seconds:.2f} s"
                     + (f", {len(self.cameras)} training cameras" if self.cameras else ""))
        if first:
            self.frame_count = 0
        if self._cli_cameras is not None:
            path, self._cli_cameras = self._cli_cameras, None
            self._needs_reset = False
            self.reset_camera()
            self.open_cameras(path)

    # ---- camera -------------------------------------------------------------------------------------------------

    def reset_camera(self) -> None:
        if self.scene is None:
            return
        lo, hi = self.scene.robust_bounds()
        r = self.panes[0].rect
        self.controller.up = self.settings.up
        self.controller.fov_y_deg = self.settings.fov_y_deg
        self.controller.frame_bounds(lo, hi, aspect=r.w / max(1, r.h) if r.w > 1 else 4 / 3)
        self.cam_index = -1
        self.moved()

    def step_camera(self, direction: int) -> None:
        if not self.cameras:
            self.message("no training cameras: open a cameras.json (or put one next to the scene)", YELLOW)
            return
        self.cam_index = (self.cam_index + direction) % len(self.cameras)
        cam = self.cameras[self.cam_index]
        if self.scene is not None:
            lo, hi = self.scene.robust_bounds()
            self.controller.centre = (np.asarray(lo, np.float64) + hi) / 2
            self.controller.radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
        self.controller.snap_to(cam)
        self.settings.fov_y_deg = self.controller.fov_y_deg
        self.moved()

    def set_up(self, up: str) -> None:
        self.settings.up = up
        self.controller.set_up(up)
        self.moved()

    def moved(self) -> None:
        self.last_move = time.perf_counter()

    @property
    def moving(self) -> bool:
        return time.perf_counter() - self.last_move < MOVING_HOLD_S

    # ---- settings -----------------------------------------------------------------------------------------------

    def set_rate(self, rate: float) -> None:
        self.settings.rate = logic.clamp_rate(rate)

    def set_pane_count(self, n: int) -> None:
        self.settings.pane_count = min(logic.MAX_PANES, max(1, int(n)))

    def pane_settings(self, i: int) -> PaneSettings:
        return self.settings.panes[i]

    def set_pane(self, i: int, **changes) -> None:
        p = self.settings.panes[i]
        for k, v in changes.items():
            setattr(p, k, v)
        self.settings.panes[i] = p.normalised()

    def cycle_mode(self, i: int, direction: int = 1) -> None:
        names = logic.MODE_NAMES
        p = self.settings.panes[i]
        self.set_pane(i, mode=names[(names.index(p.mode) + direction) % len(names)])

    def message(self, text: str, colour: int = WHITE) -> None:
        self.messages.append((time.perf_counter(), text, colour))
        self.messages = self.messages[-6:]

    def save_settings(self) -> None:
        if not self.persist:
            return
        try:
            if not glfw.get_window_attrib(self.window, glfw.ICONIFIED):
                self.settings.window = tuple(glfw.get_window_size(self.window))
            self.settings.fov_y_deg = self.controller.fov_y_deg
            logic.save_settings(self.settings, self.settings_file)
        except (OSError, GBViewerError) as exc:
            print(f"gbviewer: could not save settings: {exc}")

    # ---- the frame loop -----------------------------------------------------------------------------------------

    def run(self) -> None:
        try:
            while not glfw.window_should_close(self.window) and not self.closed:
                busy = (self.moving or self.loader is not None or self.worker.busy() or self.fly
                        or (self.video is not None and not self.video.finished()))
                if busy:
                    glfw.poll_events()
                else:
                    glfw.wait_events_timeout(0.1)
                self.step(poll=False)
        finally:
            self.close()

    def run_frames(self, n: int) -> None:
        for _ in range(n):
            self.step()

    def wait_rendered(self, timeout: float = 120.0) -> bool:
        """Step until the scene is loaded and every visible pane shows its latest full-resolution request."""
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < timeout:
            self.step()
            if self.loader is None and self.scene is not None and self.frame_count > 2 and self.all_current():
                self.step()
                return True
            time.sleep(0.01)
        return False

    def all_current(self) -> bool:
        for p in self.panes[: self.settings.pane_count]:
            for part in self._parts(p.index):
                key = p.submitted.get(part)
                shown = p.parts[part]
                if key is None or shown.job is None or shown.job.info.get("key") != key:
                    return False
                if shown.job.info.get("preview", 1.0) != 1.0:
                    return False
        return not self.worker.busy()

    def _parts(self, i: int) -> tuple[str, ...]:
        return ("a", "b") if self.settings.panes[i].split else ("a",)

    def step(self, poll: bool = True) -> None:
        """One UI frame: events, finished renders, the UI, new render requests, draw, swap."""
        if self.closed:
            return
        if poll:
            glfw.poll_events()
        self._poll_loader()
        self._poll_results()
        self._poll_dialog()
        self._poll_video()
        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        if self.font is not None:
            imgui.push_font(self.font, 16.0)
        self._layout()
        if self._needs_reset:
            self._needs_reset = False
            self.reset_camera()
        self._handle_input()
        self._draw_menu()
        self._draw_panel()
        self._draw_panes()
        self._draw_status()
        self._draw_loupe()
        self._draw_help()
        self._draw_browser()
        if self.font is not None:
            imgui.pop_font()
        imgui.render()
        self._submit_renders()
        fw, fh = glfw.get_framebuffer_size(self.window)
        self.ctx.screen.use()
        self.ctx.viewport = (0, 0, fw, fh)
        self.ctx.clear(0.07, 0.075, 0.085, 1.0)
        io = imgui.get_io()
        scale = (io.display_framebuffer_scale.x or 1.0, io.display_framebuffer_scale.y or 1.0)
        self.blit_panes.flush(fw, fh, scale)
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        self.blit_loupe.flush(fw, fh, scale)
        if self._pending_screenshot is not None:
            path, self._pending_screenshot = self._pending_screenshot, None
            self._write_window_png(path)
        glfw.swap_buffers(self.window)
        self.frame_count += 1
        self.ui_fps.tick()

    def close(self) -> None:
        if self.closed:
            return
        self.save_settings()
        self.closed = True
        if self.video is not None:
            self.video.cancel(wait=10.0)
        self.worker.stop()
        for p in self.panes:
            for s in p.parts.values():
                if s.texture is not None:
                    s.texture.release()
        self.blit_panes.release()
        self.blit_loupe.release()
        imgui.backends.opengl3_shutdown()
        imgui.backends.glfw_shutdown()
        imgui.destroy_context()
        glfw.destroy_window(self.window)
        glfw.terminate()

    # ---- geometry -----------------------------------------------------------------------------------------------

    def _layout(self) -> None:
        io = imgui.get_io()
        w, h = io.display_size.x, io.display_size.y
        top = imgui.get_frame_height()
        bottom = imgui.get_frame_height() + 6
        self.viewport = Rect(PANEL_W, int(top), max(1, int(w) - PANEL_W), max(1, int(h - top - bottom)))
        v = self.viewport
        rects = logic.pane_rects(v.x + 4, v.y + 4, v.w - 8, v.h - 8, self.settings.pane_count, self.settings.layout)
        sx, sy = io.display_framebuffer_scale.x or 1.0, io.display_framebuffer_scale.y or 1.0
        for p, r in zip(self.panes, rects):
            p.rect = r
            p.render_size = logic.render_size(round(r.w * sx), round(r.h * sy), self.settings.rate)

    def pane_at(self, x: float, y: float) -> int | None:
        for p in self.panes[: self.settings.pane_count]:
            if p.rect.contains(x, y):
                return p.index
        return None

    # ---- input --------------------------------------------------------------------------------------------------

    def _handle_input(self) -> None:
        io = imgui.get_io()
        mx, my = io.mouse_pos.x, io.mouse_pos.y
        over = self.pane_at(mx, my) if not io.want_capture_mouse else None
        if over is not None:
            r = self.panes[over].rect
            self.hover = (over, (mx - r.x) / r.w, (my - r.y) / r.h)
        elif not io.want_capture_mouse:
            self.hover = None
        c = self.controller
        # split divider
        if self.dragging_split is not None:
            if imgui.is_mouse_down(0):
                r = self.panes[self.dragging_split].rect
                self.set_pane(self.dragging_split, split_pos=(mx - r.x) / r.w)
            else:
                self.dragging_split = None
        elif over is not None and imgui.is_mouse_clicked(0) and self.settings.panes[over].split:
            r = self.panes[over].rect
            if abs(mx - (r.x + self.settings.panes[over].split_pos * r.w)) <= 7:
                self.dragging_split = over
        if over is not None or self._dragging_view():
            dx, dy = io.mouse_delta.x, io.mouse_delta.y
            if self.dragging_split is None and imgui.is_mouse_dragging(0, 0.0) and (dx or dy):
                (c.look if self.fly else c.orbit)(dx, dy)
                self.moved()
            if (imgui.is_mouse_dragging(1, 0.0) or imgui.is_mouse_dragging(2, 0.0)) and (dx or dy):
                c.pan(dx, dy, self.panes[0].rect.h)
                self.moved()
            if io.mouse_wheel and over is not None:
                c.dolly(io.mouse_wheel)
                self.moved()
        if io.want_text_input:
            return
        K = imgui.Key
        pressed = imgui.is_key_pressed
        shift, ctrl = io.key_shift, io.key_ctrl
        if pressed(K.f1, False) or (shift and pressed(K.slash, False)):
            self.show_help = not self.show_help
        if pressed(K.escape, False):
            self.show_help, self.fly = False, False
            self._browser = None
        if ctrl and pressed(K.o, False):
            self.open_dialog()
        if ctrl and pressed(K.q, False):
            glfw.set_window_should_close(self.window, True)
        if ctrl:
            return
        if pressed(K.f12, False):
            if shift and self.hover is not None:
                self.screenshot_pane(self.hover[0])
            elif not shift:
                self.screenshot_window()
        if pressed(K.f, False):
            self.fly = not self.fly
        if pressed(K.r, False):
            self.reset_camera()
        if pressed(K.left_bracket, True):
            self.step_camera(-1)
        if pressed(K.right_bracket, True):
            self.step_camera(1)
        if pressed(K.u, False):
            axes = list(UP_AXES)
            self.set_up(axes[(axes.index(self.settings.up) + 1) % len(axes)])
        if pressed(K.minus, True):
            self.set_rate(logic.step_rate(self.settings.rate, -1))
        if pressed(K.equal, True):
            self.set_rate(logic.step_rate(self.settings.rate, +1))
        if pressed(K._0, False):
            self.set_rate(1.0)
        for n, key in enumerate((K._1, K._2, K._3, K._4), start=1):
            if pressed(key, False):
                self.set_pane_count(n)
        if pressed(K.g, False):
            self.settings.layout = "grid" if self.settings.layout == "row" else "row"
        if pressed(K.l, False):
            self.settings.loupe = not self.settings.loupe
        if pressed(K.i, False):
            self.settings.show_info = not self.settings.show_info
        target = self.hover[0] if self.hover is not None else 0
        if pressed(K.m, False):
            self.cycle_mode(target, -1 if shift else 1)
        if pressed(K.v, False):
            self.set_pane(target, split=not self.settings.panes[target].split)
        if self.fly:
            down = imgui.is_key_down
            fwd = down(K.w) - down(K.s)
            right = down(K.d) - down(K.a)
            upward = down(K.e) - down(K.q)
            if fwd or right or upward:
                c.fly(fwd, right, upward, io.delta_time, self.settings.fly_speed * (4 if shift else 1))
                self.moved()

    def _dragging_view(self) -> bool:
        return any(imgui.is_mouse_dragging(b, 0.0) for b in (0, 1, 2)) and self.hover is not None \
            and not imgui.get_io().want_capture_mouse

    # ---- rendering requests and results ---------------------------------------------------------------------------

    def _settings_for(self, ps: PaneSettings, part: str) -> RenderSettings:
        mode = Mode.parse(ps.split_mode if part == "b" else ps.mode)
        debug = "window" if ps.view == "window" and mode == Mode.GAUSSIAN_BLENDING else "none"
        return RenderSettings(mode, ps.supersample, self.settings.background, debug=debug)

    def pane_camera(self, i: int, preview: float = 1.0):
        """The camera pane i renders with at the current rate (x `preview` while moving)."""
        p = self.panes[i]
        io = imgui.get_io()
        sx, sy = io.display_framebuffer_scale.x or 1.0, io.display_framebuffer_scale.y or 1.0
        base = self.controller.camera(round(p.rect.w * sx), round(p.rect.h * sy))
        return base.at_sampling_rate(self.settings.rate * preview)

    def _submit_renders(self) -> None:
        if self.scene is None:
            return
        backend = self.settings.backend if self.backend_usable(self.settings.backend) else "cpu"
        state = self.controller.state()
        moving = self.moving
        slots = sum(len(self._parts(i)) for i in range(self.settings.pane_count))
        for p in self.panes[: self.settings.pane_count]:
            ps = self.settings.panes[p.index]
            for part in self._parts(p.index):
                w, h = p.render_size
                f = logic.preview_factor(w * h, p.ms_per_px.get((part, ps.mode if part == "a" else ps.split_mode,
                                                                 ps.supersample, backend)),
                                         PREVIEW_BUDGET_MS * 2 / max(2, slots), moving)
                cam = self.pane_camera(p.index, f)
                settings = self._settings_for(ps, part)
                samples = cam.width * cam.height * settings.supersample ** 2
                if samples > MAX_SAMPLES:
                    p.parts[part].error = (f"{cam.width}x{cam.height} with {settings.supersample}x"
                                           f"{settings.supersample} samples is {samples / 1e6:.0f}M samples, over "
                                           f"the {MAX_SAMPLES // 1_000_000}M limit: lower the rate or supersampling")
                    p.submitted.pop(part, None)
                    continue
                if "M limit: lower" in p.parts[part].error:
                    p.parts[part].error = ""
                key = (id(self.scene), state, (cam.width, cam.height), settings, backend)
                if moving and (os.cpu_count() or 1) > 1:  # leave a core to the UI thread while the camera moves
                    settings = replace(settings, threads=(os.cpu_count() or 2) - 1)
                if p.submitted.get(part) == key:
                    continue
                p.submitted[part] = key
                self.worker.submit(RenderJob((p.index, part), self.scene, cam, settings, backend,
                                             {"key": key, "preview": f, "rate": self.settings.rate,
                                              "full_size": (w, h)}))

    def _poll_results(self) -> None:
        for res in self.worker.results():
            self._take_result(res)
        for p in self.panes[: self.settings.pane_count]:  # a view change re-colours the frame it has
            view = self.settings.panes[p.index].view
            for shown in p.parts.values():
                if shown.frame is not None and shown.view != view:
                    self._upload(shown, shown.frame, view)

    def _take_result(self, res: RenderResult) -> None:
        i, part = res.job.slot
        if res.job.scene is not self.scene:
            return
        p = self.panes[i]
        shown = p.parts[part]
        if res.frame is None:
            shown.error, shown.job = res.error, res.job
            self.message(f"pane {p.name}: {res.error}", RED)
            return
        shown.error = ""
        shown.job = res.job
        st = res.frame.stats
        cam = res.job.camera
        if res.job.info.get("preview", 1.0) == 1.0 and st.total_ms:
            p.ms_per_px[(part, res.job.settings.mode.label, res.job.settings.supersample, res.job.backend)] = \
                st.total_ms / (cam.width * cam.height)
        p.fps[part].tick(res.finished)
        self._upload(shown, res.frame, self.settings.panes[i].view)

    def _upload(self, shown: Shown, frame, view: str) -> None:
        rgb, legend = logic.visualize(frame, view)
        img = np.ascontiguousarray(to_uint8(rgb))
        h, w = img.shape[:2]
        tex = shown.texture
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            tex = self.ctx.texture((w, h), 3, img.tobytes(), alignment=1)
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
        else:
            tex.write(img.tobytes(), alignment=1)
        shown.texture, shown.frame, shown.view, shown.legend, shown.image = tex, frame, view, legend, img

    # ---- backends -----------------------------------------------------------------------------------------------

    def backend_status(self, name: str) -> tuple[bool | None, str]:
        """(usable, reason); None while the render thread is still probing."""
        if name not in BACKENDS:
            return False, "not part of this installation"
        if not self.worker.backends_ready.is_set():
            return None, "checking..."
        return self.worker.backends.get(name, (False, "unknown"))

    def backend_usable(self, name: str) -> bool:
        return self.backend_status(name)[0] is True

    # ---- output -------------------------------------------------------------------------------------------------

    def shot_dir(self) -> Path:
        return Path(self.settings.screenshot_dir or Path.cwd() / "screenshots").expanduser()

    def _shot_name(self, what: str) -> Path:
        stem = self.scene_path.stem if self.scene_path else "gbviewer"
        base = self.shot_dir() / f"{stem}-{what}-{time.strftime('%Y%m%d-%H%M%S')}"
        path, k = base.with_suffix(".png"), 1
        while path.exists():
            k += 1
            path = base.parent / f"{base.name}-{k}.png"
        return path

    def screenshot_window(self, path: str | Path | None = None) -> Path:
        """Queue a PNG of the whole window (written at the end of this frame, after drawing)."""
        path = Path(path) if path else self._shot_name("window")
        self._pending_screenshot = path
        return path

    def read_window(self) -> np.ndarray:
        """The last drawn window contents, (H, W, 3) uint8, row 0 at the top (call right after step())."""
        fw, fh = glfw.get_framebuffer_size(self.window)
        self.ctx.screen.use()
        data = self.ctx.screen.read(viewport=(0, 0, fw, fh), components=3, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(fh, fw, 3)[::-1].copy()

    def _write_window_png(self, path: Path) -> None:
        from PIL import Image

        img = self.read_window()
        try:
            atomic_write(path, lambda p: Image.fromarray(img).save(p, format="PNG"), force=True)
            self.message(f"saved {path}")
            self.last_screenshot = path
        except OSError as exc:
            self.message(f"screenshot failed: {exc}", RED)

    def screenshot_pane(self, i: int, path: str | Path | None = None, part: str = "a") -> Path | None:
        """The pane's last render at its render resolution, 16 bits per channel (full precision)."""
        shown = self.panes[i].parts[part]
        if shown.frame is None:
            self.message(f"pane {PANE_NAMES[i]} has no image yet", YELLOW)
            return None
        rgb, _ = logic.visualize(shown.frame, shown.view or "color")
        path = Path(path) if path else self._shot_name(f"pane{PANE_NAMES[i]}")
        data = logic.encode_png16(rgb)
        try:
            atomic_write(path, lambda p: p.write_bytes(data), force=True)
        except OSError as exc:
            self.message(f"screenshot failed: {exc}", RED)
            return None
        self.message(f"saved {path}")
        return path

    # ---- file dialogs -------------------------------------------------------------------------------------------

    def open_dialog(self, cameras: bool = False) -> None:
        """The system's file dialog (portable-file-dialogs, when zenity or kdialog exists), else a built-in one."""
        start = str(self.scene_path.parent if self.scene_path else Path.cwd())
        if any(shutil.which(p) for p in DIALOG_PROGRAMS):
            from imgui_bundle import portable_file_dialogs as pfd

            filters = ["Splat scenes", "*.ply *.splat *.spz *.sog *.json", "All files", "*"]
            self._file_dialog = pfd.open_file("Open a scene or cameras.json", start, filters)
        else:
            self._browser = {"dir": Path(start), "filter": ""}

    def _poll_dialog(self) -> None:
        if self._file_dialog is not None and self._file_dialog.ready(0):
            result = self._file_dialog.result()
            self._file_dialog = None
            for p in result or []:
                self.open(p)

    # ---- drawing --------------------------------------------------------------------------------------------------

    def _draw_menu(self) -> None:
        if not imgui.begin_main_menu_bar():
            return
        if imgui.begin_menu("File"):
            if imgui.menu_item("Open scene or cameras.json...", "Ctrl+O", False)[0]:
                self.open_dialog()
            if imgui.begin_menu("Open recent", bool(self.settings.recent)):
                for r in self.settings.recent:
                    exists = Path(r).exists()
                    if imgui.menu_item(r, "", False, exists)[0]:
                        self.open(r)
                imgui.end_menu()
            imgui.separator()
            if imgui.menu_item("Screenshot of the window", "F12", False)[0]:
                self.screenshot_window()
            for p in self.panes[: self.settings.pane_count]:
                if imgui.menu_item(f"Screenshot of pane {p.name} (16-bit, render resolution)", "", False)[0]:
                    self.screenshot_pane(p.index)
            imgui.separator()
            if imgui.menu_item("Quit", "Ctrl+Q", False)[0]:
                glfw.set_window_should_close(self.window, True)
            imgui.end_menu()
        if imgui.begin_menu("View"):
            for n in range(1, 5):
                if imgui.menu_item(f"{n} pane{'s' if n > 1 else ''}", str(n), self.settings.pane_count == n)[0]:
                    self.set_pane_count(n)
            if imgui.menu_item("2x2 grid", "G", self.settings.layout == "grid")[0]:
                self.settings.layout = "grid" if self.settings.layout == "row" else "row"
            if imgui.menu_item("Magnifier loupe", "L", self.settings.loupe)[0]:
                self.settings.loupe = not self.settings.loupe
            if imgui.menu_item("Information overlay", "I", self.settings.show_info)[0]:
                self.settings.show_info = not self.settings.show_info
            imgui.end_menu()
        if imgui.begin_menu("Camera"):
            if imgui.menu_item("Reset", "R", False)[0]:
                self.reset_camera()
            if imgui.menu_item("Fly mode", "F", self.fly)[0]:
                self.fly = not self.fly
            if imgui.menu_item("Next training camera", "]", False, bool(self.cameras))[0]:
                self.step_camera(1)
            if imgui.menu_item("Previous training camera", "[", False, bool(self.cameras))[0]:
                self.step_camera(-1)
            imgui.end_menu()
        if imgui.begin_menu("Help"):
            if imgui.menu_item("Shortcuts", "F1", self.show_help)[0]:
                self.show_help = not self.show_help
            imgui.end_menu()
        hint = "F1 or ? : shortcuts"
        imgui.same_line(imgui.get_io().display_size.x - imgui.calc_text_size(hint).x - 16)
        imgui.text_disabled(hint)
        imgui.end_main_menu_bar()

    def _section(self, title: str) -> bool:
        imgui.spacing()
        return imgui.collapsing_header(title, imgui.TreeNodeFlags_.default_open.value)

    def _draw_panel(self) -> None:
        v = self.viewport
        imgui.set_next_window_pos((0, v.y))
        imgui.set_next_window_size((PANEL_W, v.h))
        flags = (imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_move
                 | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_bring_to_front_on_focus).value
        imgui.begin("##panel", None, flags)
        s = self.settings
        # scene
        if self._section("Scene"):
            if self.scene is not None:
                name = self.scene_path.name if self.scene_path else "?"
                imgui.text(name)
                imgui.text_disabled(f"{self.scene.num_splats:,} splats, SH degree {self.scene.sh_degree}, "
                                    f"{self.scene.meta.get('format', '?')}")
            if self.loader is not None:
                t = self.loader.elapsed
                size = f" ({self.loader.size / 1e6:.1f} MB)" if self.loader.size else ""
                imgui.text(f"Loading {self.loader.path.name}{size}")
                imgui.progress_bar(-1.0 * t, (PANEL_W - 24, 0), f"{t:.1f} s")
            if self.load_error:
                imgui.push_text_wrap_pos(PANEL_W - 16)
                imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), self.load_error)
                imgui.pop_text_wrap_pos()
                if imgui.small_button("dismiss"):
                    self.load_error = ""
            if imgui.button("Open..."):
                self.open_dialog()
            imgui.same_line()
            if imgui.begin_combo("##recent", "Recent files"):
                for r in s.recent:
                    if imgui.selectable(r, False, 0 if Path(r).exists() else
                                        imgui.SelectableFlags_.disabled.value)[0]:
                        self.open(r)
                if not s.recent:
                    imgui.text_disabled("(none yet)")
                imgui.end_combo()
        # backend
        if self._section("Backend"):
            names = list(dict.fromkeys([*BACKENDS, *KNOWN_BACKENDS]))
            for name in names:
                ok, why = self.backend_status(name)
                imgui.begin_disabled(ok is not True)
                if imgui.radio_button(name, s.backend == name) and ok:
                    s.backend = name
                imgui.end_disabled()
                if ok is not True:
                    imgui.same_line()
                    imgui.push_text_wrap_pos(PANEL_W - 16)
                    imgui.text_disabled(why if len(why) < 140 else why[:137] + "...")
                    imgui.pop_text_wrap_pos()
            if not self.backend_usable(s.backend) and self.worker.backends_ready.is_set():
                imgui.text_colored(imgui.ImVec4(1, 0.8, 0.25, 1), f"{s.backend} unavailable: rendering on cpu")
        # sampling rate
        if self._section("Sampling rate (all panes)"):
            for k, r in enumerate(logic.RATE_STEPS):
                if k:
                    imgui.same_line(0, 3)
                active = abs(s.rate - r) < 1e-9
                if active:
                    imgui.push_style_color(imgui.Col_.button.value, imgui.ImVec4(0.24, 0.47, 0.80, 1))
                if imgui.button(logic.format_rate(r), (38, 0)):
                    self.set_rate(r)
                if active:
                    imgui.pop_style_color()
            imgui.set_next_item_width(PANEL_W - 24)
            changed, val = imgui.slider_float("##rate", logic.rate_to_slider(s.rate), -3.0, 3.0,
                                              logic.format_rate(s.rate))
            if changed:
                self.set_rate(logic.slider_to_rate(val))
            sizes = ", ".join(f"{p.name} {p.render_size[0]}x{p.render_size[1]}"
                              for p in self.panes[: s.pane_count])
            imgui.push_text_wrap_pos(PANEL_W - 16)
            imgui.text_disabled(f"render: {sizes}")
            imgui.pop_text_wrap_pos()
        # panes
        if self._section("Panes"):
            for n in range(1, 5):
                if n > 1:
                    imgui.same_line()
                if imgui.radio_button(f"{n}##panes", s.pane_count == n):
                    self.set_pane_count(n)
            imgui.same_line(0, 18)
            if imgui.radio_button("row", s.layout == "row"):
                s.layout = "row"
            imgui.same_line()
            if imgui.radio_button("2x2", s.layout == "grid"):
                s.layout = "grid"
            modes = list(logic.MODE_NAMES)
            for p in self.panes[: s.pane_count]:
                ps = s.panes[p.index]
                imgui.push_id(p.index)
                imgui.separator_text(f"Pane {p.name}")
                imgui.set_next_item_width(170)
                ch, k = imgui.combo("mode", modes.index(ps.mode), modes)
                if ch:
                    self.set_pane(p.index, mode=modes[k])
                imgui.set_next_item_width(170)
                ch, ss = imgui.slider_int("supersample", ps.supersample, 1, 8, "%dx%d" % (ps.supersample,
                                                                                      ps.supersample))
                if ch:
                    self.set_pane(p.index, supersample=ss)
                imgui.set_next_item_width(170)
                ch, k = imgui.combo("view", logic.VIEWS.index(ps.view), list(logic.VIEWS))
                if ch:
                    self.set_pane(p.index, view=logic.VIEWS[k])
                if imgui.is_item_hovered():
                    imgui.set_tooltip("\n".join(f"{k}: {v}" for k, v in logic.VIEW_HELP.items()))
                ch, on = imgui.checkbox("split with", ps.split)
                if ch:
                    self.set_pane(p.index, split=on)
                imgui.same_line()
                imgui.begin_disabled(not ps.split)
                imgui.set_next_item_width(150)
                ch, k = imgui.combo("##splitmode", modes.index(ps.split_mode), modes)
                if ch:
                    self.set_pane(p.index, split_mode=modes[k])
                imgui.end_disabled()
                imgui.pop_id()
        # camera
        if self._section("Camera"):
            if imgui.button("Reset (R)"):
                self.reset_camera()
            imgui.same_line()
            ch, self.fly = imgui.checkbox("fly mode (F)", self.fly)
            imgui.set_next_item_width(170)
            ch, fov = imgui.slider_float("field of view", self.controller.fov_y_deg, 5.0, 120.0, "%.0f deg")
            if ch:
                self.controller.set_fov(fov)
                s.fov_y_deg = self.controller.fov_y_deg
                self.moved()
            axes = list(UP_AXES)
            imgui.set_next_item_width(170)
            ch, k = imgui.combo("up axis (U)", axes.index(s.up), axes)
            if ch:
                self.set_up(axes[k])
            if self.fly:
                imgui.set_next_item_width(170)
                _, s.fly_speed = imgui.slider_float("fly speed", s.fly_speed, 0.05, 5.0, "%.2f radii/s",
                                                    imgui.SliderFlags_.logarithmic.value)
            if self.cameras:
                if imgui.arrow_button("##prev", imgui.Dir.left):
                    self.step_camera(-1)
                imgui.same_line()
                if imgui.arrow_button("##next", imgui.Dir.right):
                    self.step_camera(1)
                imgui.same_line()
                cur = self.cameras[self.cam_index].name if self.cam_index >= 0 else "free camera"
                imgui.text(f"training {self.cam_index + 1}/{len(self.cameras)}: {cur}")
            else:
                imgui.text_disabled("no training cameras (cameras.json)")
            if imgui.small_button("Open cameras.json..."):
                self.open_dialog(cameras=True)
        # magnifier and output
        if self._section("Magnifier and output"):
            _, s.loupe = imgui.checkbox("loupe (L)", s.loupe)
            imgui.same_line()
            imgui.set_next_item_width(120)
            _, s.loupe_zoom = imgui.slider_float("zoom", s.loupe_zoom, 2.0, 32.0, "x%.0f")
            if imgui.button("Screenshot window (F12)"):
                self.screenshot_window()
            for p in self.panes[: s.pane_count]:
                if p.index:
                    imgui.same_line(0, 4)
                if imgui.button(p.name):
                    self.screenshot_pane(p.index)
                if imgui.is_item_hovered():
                    imgui.set_tooltip(f"pane {p.name}: 16-bit PNG at its render resolution")
            imgui.text_disabled(f"into {self.shot_dir()}")
            self._draw_video_button()
        # stats
        if self._section("Timings"):
            self._draw_stats_table()
        imgui.end()

    def record_video(self, frames: int | None = None, out: str | Path | None = None) -> VideoJob | None:
        """Start the zoom video (x1 to x1/8) of the current view, one column per visible pane's mode, in the
        background; 480 px wide panes with the panes' aspect."""
        if self.scene is None or (self.video is not None and not self.video.finished()):
            return None
        r = self.panes[0].rect
        w = VIDEO_PANE_W
        h = max(2, round(w * r.h / max(1, r.w) / 2) * 2)
        cam = self.controller.camera(w, h)
        settings = [self._settings_for(self.settings.panes[i], "a") for i in range(self.settings.pane_count)]
        settings = [RenderSettings(s.mode, s.supersample, s.background) for s in settings]
        out = Path(out) if out else self._shot_name("zoom").with_suffix(".mp4")
        self.video = VideoJob(self.scene, cam, settings, out, frames or self.video_frames)
        self.message(f"recording {out.name} ({self.video.total} frames) in the background")
        return self.video

    def _poll_video(self) -> None:
        v = self.video
        if v is None or not v.finished() or getattr(v, "reported", False):
            return
        v.reported = True
        if v.error:
            self.message(f"video: {v.error}", YELLOW if v.cancelled else RED)
        elif v.info is not None:
            self.message(f"saved {v.info.path} ({v.info.frames} frames, {v.info.elapsed_s:.0f} s)")

    def _draw_video_button(self) -> None:
        if not self.video_ok:
            return  # gbviewer.video without record_video: no button
        v = self.video
        if v is not None and not v.finished():
            imgui.progress_bar(v.fraction, (PANEL_W - 100, 0), f"video {v.done_frames}/{v.total}")
            imgui.same_line()
            if imgui.button("Cancel"):
                v.cancel()
            return
        if imgui.button("Record zoom video"):
            self.record_video()
        if imgui.is_item_hovered():
            imgui.set_tooltip("x1 to x1/8 zoom of this view, one column per pane's mode (H.264 MP4), rendered in "
                              "the background")
        imgui.same_line()
        imgui.set_next_item_width(110)
        _, self.video_frames = imgui.slider_int("frames", self.video_frames, 15, 300)

    def _draw_stats_table(self) -> None:
        flags = (imgui.TableFlags_.borders_inner_h | imgui.TableFlags_.row_bg | imgui.TableFlags_.sizing_fixed_fit
                 ).value
        if not imgui.begin_table("stats", 6, flags):
            return
        for h in ("", "total", "pre", "sort", "blend", "fps"):
            imgui.table_setup_column(h)
        imgui.table_headers_row()
        for p in self.panes[: self.settings.pane_count]:
            for part in self._parts(p.index):
                shown = p.parts[part]
                if shown.frame is None:
                    continue
                st = shown.frame.stats
                imgui.table_next_row()
                cells = (p.name + ("'" if part == "b" else ""), f"{st.total_ms:.0f}",
                         f"{st.preprocess_ms:.1f}", f"{st.sort_ms:.1f}",
                         f"{st.blend_ms:.0f}", f"{self.pane_fps(p, part):.1f}")
                for c in cells:
                    imgui.table_next_column()
                    imgui.text(c)
        imgui.end_table()
        imgui.text_disabled("ms per stage; fps = finished renders per second")
        imgui.text_disabled(f"UI {self.ui_fps.rate():.0f} fps, {self.worker.dropped} stale requests dropped")

    def pane_fps(self, p: PaneState, part: str) -> float:
        """Finished renders per second over the last 2 s while they keep coming, else 1000 / the last total."""
        rate = p.fps[part].rate()
        frame = p.parts[part].frame
        if rate > 0 or frame is None:
            return rate
        return 1000.0 / max(1e-3, frame.stats.total_ms)

    def _text(self, dl, x: float, y: float, text: str, colour: int = WHITE, bg: int = BLACK_A,
              align_right: bool = False) -> tuple[float, float]:
        if self.mono is not None:
            imgui.push_font(self.mono, 15.0)
        size = imgui.calc_text_size(text)
        if align_right:
            x -= size.x + 8
        dl.add_rect_filled((x, y), (x + size.x + 8, y + size.y + 4), bg, 3.0)
        dl.add_text((x + 4, y + 2), colour, text)
        if self.mono is not None:
            imgui.pop_font()
        return size.x + 8, size.y + 4

    def _label(self, p: PaneState, part: str) -> str:
        ps = self.settings.panes[p.index]
        shown = p.parts[part]
        job = shown.job
        if job is None:
            return f"{p.name}  {ps.mode if part == 'a' else ps.split_mode}"
        label = job.settings.label_for(self.scene) if self.scene is not None else job.settings.label
        rate = logic.format_rate(job.info.get("rate", self.settings.rate))
        w, h = job.info.get("full_size", (job.camera.width, job.camera.height))
        name = p.name + ("'" if part == "b" else "")
        view = f"  [{shown.view}]" if shown.view and shown.view != "color" else ""
        return f"{name}  {label}  {rate}  {w}x{h}{view}"

    def _draw_panes(self) -> None:
        dl = imgui.get_background_draw_list()
        v = self.viewport
        if self.loader is not None:  # over the previous scene, which stays until the new one is ready
            size = f", {self.loader.size / 1e6:.1f} MB" if self.loader.size else ""
            y = v.y + v.h / 2 if self.scene is None else v.y + 40
            self._banner(dl, f"loading {self.loader.path.name}{size} ... {self.loader.elapsed:.1f} s", y, WHITE)
        if self.scene is None:
            return
        for p in self.panes[: self.settings.pane_count]:
            r = p.rect
            ps = self.settings.panes[p.index]
            parts = self._parts(p.index)
            ranges = logic.split_parts(ps.split_pos) if ps.split else ((0.0, 1.0),)
            for part, (u0, u1) in zip(parts, ranges):
                shown = p.parts[part]
                if shown.texture is None or u1 <= u0:
                    continue
                x0, x1 = r.x + u0 * r.w, r.x + u1 * r.w
                self.blit_panes.add(shown.texture, x0, r.y, x1, r.y + r.h, (u0, 0.0, u1, 1.0))
            # overlays, clipped to the pane
            dl.push_clip_rect((r.x, r.y), (r.x + r.w, r.y + r.h), True)
            y = r.y + 4
            self._text(dl, r.x + 4, y, self._label(p, "a"))
            if ps.split:
                self._text(dl, r.x + r.w - 4, y, self._label(p, "b"), align_right=True)
                sx = r.x + ps.split_pos * r.w
                dl.add_line((sx, r.y), (sx, r.y + r.h), col(255, 255, 255, 220), 2.0)
                dl.add_circle_filled((sx, r.y + r.h / 2), 7, col(255, 255, 255, 230))
                dl.add_circle((sx, r.y + r.h / 2), 7, col(0, 0, 0, 200), 0, 1.5)
            y += 26
            for part in parts:
                shown = p.parts[part]
                job = shown.job
                right = part == "b"
                xx = r.x + r.w - 4 if right else r.x + 4
                if job is not None and job.info.get("preview", 1.0) < 1.0:
                    fw, fh = job.info["full_size"]
                    self._text(dl, xx, y, f"moving: preview {job.camera.width}x{job.camera.height} "
                                          f"(not {fw}x{fh})", YELLOW, align_right=right)
                elif self.worker.busy((p.index, part)) and shown.job is not None:
                    self._text(dl, xx, y, "rendering...", GREY, align_right=right)
                if shown.error:
                    self._text(dl, r.x + 4, r.y + r.h / 2, shown.error[:120], RED)
                if shown.legend:
                    self._text(dl, xx, r.y + 56, shown.legend, ACCENT, align_right=right)
            if self.settings.show_info:
                lines = []
                for part in parts:
                    shown = p.parts[part]
                    if shown.frame is None:
                        continue
                    st = shown.frame.stats
                    tag = "B " if part == "b" else ""
                    lines.append(f"{tag}{st.total_ms:.1f} ms: pre {st.preprocess_ms:.1f}"
                                 f" + sort {st.sort_ms:.1f} + blend {st.blend_ms:.1f}"
                                 f"  {self.pane_fps(p, part):.1f} fps")
                    lines.append(f"{tag}{int(st.visible):,} splats visible"
                                 f"  {st.evals_per_pixel:.0f} evals/px")
                for k, line in enumerate(reversed(lines)):
                    self._text(dl, r.x + 4, r.y + r.h - 24 - 21 * k, line, col(220, 220, 220))
            if self.hover is not None and self.hover[0] == p.index:
                dl.add_rect((r.x, r.y), (r.x + r.w, r.y + r.h), col(90, 170, 255, 120), 0.0, 1.0)
            dl.pop_clip_rect()
        if self.load_error:
            self._banner(dl, self.load_error_short or self.load_error,
                         self.viewport.y + self.viewport.h - 60, RED)

    def _banner(self, dl, text: str, y: float, colour: int) -> None:
        v = self.viewport
        if self.mono is not None:
            imgui.push_font(self.mono, 15.0)
        while len(text) > 10 and imgui.calc_text_size(text).x > v.w - 24:
            text = text[: len(text) - 8] + "..."
        w = imgui.calc_text_size(text).x + 8
        if self.mono is not None:
            imgui.pop_font()
        self._text(dl, v.x + max(4, (v.w - w) / 2), y, text, colour, col(0, 0, 0, 220))

    def _draw_status(self) -> None:
        io = imgui.get_io()
        h = imgui.get_frame_height() + 6
        y = io.display_size.y - h
        imgui.set_next_window_pos((0, y))
        imgui.set_next_window_size((io.display_size.x, h))
        flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_inputs
                 | imgui.WindowFlags_.no_saved_settings).value
        imgui.push_style_var(imgui.StyleVar_.window_padding.value, imgui.ImVec2(8, 3))
        imgui.begin("##status", None, flags)
        s = self.settings
        sizes = "  ".join(f"{p.name} {p.render_size[0]}x{p.render_size[1]}" for p in self.panes[: s.pane_count])
        backend = s.backend if self.backend_usable(s.backend) else "cpu"
        simd = next((part.frame.stats.simd for p in self.panes[: s.pane_count] for part in p.parts.values()
                     if part.frame is not None and part.frame.stats.simd is not None), None)
        if backend == "cpu" and simd:
            backend = f"cpu {simd}"  # the blend's SIMD path (GBVIEWER_SIMD forces one)
        imgui.text(f"rate {logic.format_rate(s.rate)}")
        imgui.same_line(0, 16)
        imgui.text_disabled(f"render {sizes}")
        imgui.same_line(0, 16)
        imgui.text_disabled(f"{backend} | {'fly' if self.fly else 'orbit'} | up {s.up} | "
                            f"fov {self.controller.fov_y_deg:.0f}")
        now = time.perf_counter()
        recent = [m for m in self.messages if now - m[0] < 8.0]
        if recent:
            t, text, colour = recent[-1]
            imgui.same_line(0, 24)
            c = imgui.ImVec4((colour & 255) / 255, ((colour >> 8) & 255) / 255, ((colour >> 16) & 255) / 255, 1)
            imgui.text_colored(c, text)
        imgui.end()
        imgui.pop_style_var()

    def _draw_loupe(self) -> None:
        if not self.settings.loupe or self.hover is None:
            return
        io = imgui.get_io()
        dl = imgui.get_foreground_draw_list()
        _, u, v = self.hover
        n = self.settings.pane_count
        side = 160 if n <= 2 else 120
        radius = side / 2
        zoom = self.settings.loupe_zoom
        mx, my = io.mouse_pos.x, io.mouse_pos.y
        total_w = n * (side + 6)
        x = mx + 24 if mx + 24 + total_w < io.display_size.x else mx - 24 - total_w
        y = my + 24 if my + 24 + side + 24 < io.display_size.y else my - 24 - side - 24
        for k, p in enumerate(self.panes[:n]):
            ps = self.settings.panes[p.index]
            part = "b" if ps.split and u > ps.split_pos else "a"
            shown = p.parts[part]
            x0 = x + k * (side + 6)
            dl.add_rect_filled((x0 - 3, y - 3), (x0 + side + 3, y + side + 22), col(20, 22, 26, 240), 3.0)
            dl.add_rect((x0 - 2, y - 2), (x0 + side + 2, y + side + 2), col(170, 175, 185), 0.0, 2.0)
            if shown.texture is not None:
                u0, v0, u1, v1 = logic.loupe_uv(u, v, p.rect.w, p.rect.h, radius, zoom)
                self.blit_loupe.add(shown.texture, x0, y, x0 + side, y + side, (u0, v0, u1, v1))
                cx = x0 + (u - u0) / (u1 - u0) * side  # the cursor: tick marks on the frame (the image covers
                cy = y + (v - v0) / (v1 - v0) * side  # the inside, it is drawn after the UI)
                dl.add_line((cx, y - 2), (cx, y - 8), col(255, 80, 80), 2.0)
                dl.add_line((x0 - 2, cy), (x0 - 8, cy), col(255, 80, 80), 2.0)
            mode = ps.split_mode if part == "b" else ps.mode
            label = f"{p.name}{chr(39) if part == 'b' else ''} {mode}"
            while len(label) > 3 and imgui.calc_text_size(label).x > side - 6:
                label = label[:-2] + "."
            dl.add_text((x0 + 3, y + side + 3), WHITE, label)

    def _draw_help(self) -> None:
        if not self.show_help:
            return
        io = imgui.get_io()
        w, h = 720, 44 + 25 * len(logic.SHORTCUTS)
        imgui.set_next_window_pos((io.display_size.x / 2, io.display_size.y / 2), 0, (0.5, 0.5))
        imgui.set_next_window_size((w, h))
        imgui.set_next_window_bg_alpha(0.98)
        flags = (imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_move).value
        opened, keep = imgui.begin("Keyboard and mouse (F1 or ? to close)", True, flags)
        if opened and imgui.begin_table("keys", 2, imgui.TableFlags_.row_bg.value):
            imgui.table_setup_column("key", imgui.TableColumnFlags_.width_fixed.value, 170)
            imgui.table_setup_column("action")
            for key, what in logic.SHORTCUTS:
                imgui.table_next_row()
                imgui.table_next_column()
                imgui.text_colored(imgui.ImVec4(0.5, 0.75, 1.0, 1.0), key)
                imgui.table_next_column()
                imgui.text(what)
            imgui.end_table()
        imgui.end()
        if not keep:
            self.show_help = False

    def _draw_browser(self) -> None:
        """A small built-in file browser, for machines without a system file dialog program."""
        b = self._browser
        if b is None:
            return
        io = imgui.get_io()
        imgui.set_next_window_pos((io.display_size.x / 2, io.display_size.y / 2), imgui.Cond_.appearing.value,
                                  (0.5, 0.5))
        imgui.set_next_window_size((620, 460), imgui.Cond_.appearing.value)
        opened, keep = imgui.begin("Open a scene or cameras.json", True, imgui.WindowFlags_.no_collapse.value)
        if opened:
            d: Path = b["dir"]
            if imgui.button("Up"):
                b["dir"] = d.parent
            imgui.same_line()
            imgui.set_next_item_width(-1)
            ch, text = imgui.input_text("##dir", str(d), imgui.InputTextFlags_.enter_returns_true.value)
            if ch:
                t = Path(text).expanduser()
                if t.is_dir():
                    b["dir"] = t
                elif t.exists():
                    self._browser = None
                    self.open(t)
            imgui.begin_child("files", (0, -32))
            try:
                entries = sorted(d.iterdir(), key=lambda e: (not e.is_dir(), e.name.lower()))
            except OSError as exc:
                entries = []
                imgui.text_colored(imgui.ImVec4(1, 0.45, 0.4, 1), str(exc))
            for e in entries:
                if e.name.startswith("."):
                    continue
                is_dir = e.is_dir()
                if not is_dir and e.suffix.lower() not in SCENE_EXTS:
                    continue
                label = f"[{e.name}]" if is_dir else e.name
                if imgui.selectable(label, False)[0]:
                    if is_dir and not (e / "meta.json").exists():  # a folder to enter, not a SOG scene
                        b["dir"] = e
                    else:
                        self._browser = None
                        self.open(e)
                        break
            imgui.end_child()
            imgui.text_disabled("click a file to open it; a folder with meta.json opens as a SOG scene")
        imgui.end()
        if not keep:
            self._browser = None
