"""The desktop window: glfw + Dear ImGui (imgui-bundle, its C++ GLFW and OpenGL 3 backends) + moderngl.

`ViewerApp` owns the window and composes the parts: `state` (scene, panes, settings, actions), `panes` (render
requests and textures), `input` (mouse and the key map), `menu`, `panel`, `overlays`, `dialogs`, `screenshots`.
`step()` runs one UI frame and never waits for a render: renders run in `worker.RenderWorker`'s thread, each pane
shows its last finished frame, nearest-upscaled. Tests drive it with `run_frames(n)` / `wait_rendered()` and the
same methods the UI calls.
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path
from typing import Callable

import glfw
import moderngl
import numpy as np
from imgui_bundle import imgui  # must come before `import glfw`: it points pyGLFW at its own libglfw

from .. import DEFAULT_SCENE
from ..core.errors import GBViewerError
from ..render.glsl.context import release_current
from . import screenshots
from .difference.views import PaneAnalysis
from .frames.display import SharedContext, requested_path
from .inspector.state import Inspector
from .inspector.view import dock_side, draw_inspector
from .menu import draw_menu
from .overlays import labels as overlays
from .overlays.difference import draw_analysis_overlays
from .pane_state import RateMeter
from .panel import draw_panel
from .panes import PaneRenders
from .settings import AppSettings, load_settings, save_settings
from .state import AppState
from .threads.worker import RenderWorker
from .ui.blit import Blitter
from .ui.dialogs import FileDialogs, draw_help
from .ui.input import handle_input
from .ui.keys import action_table
from .ui.text import Item

WAITING_FPS = 10  # UI frames a second while renders refine or a load runs (each posted result wakes it at once)


class ViewerApp:
    """The viewer window. `ViewerApp(path).run()` is `gbviewer [SCENE]`; `data`, `images`: a training dataset
    opened beside it (`gbviewer SCENE --data DATASET --images images_4`); `background`: the panes' colour (saved;
    None: the saved one, or a dataset's photos' backdrop)."""

    def __init__(
        self,
        scene_path: str | Path | None = None,
        settings_file: Path | None = None,
        size: tuple[int, int] | None = None,
        visible: bool = True,
        persist: bool = True,
        cameras: str | Path | None = None,
        projection: str | None = None,
        backend: str | None = None,
        data: str | Path | None = None,
        images: str = "images",
        background: tuple[float, float, float] | None = None,
    ) -> None:
        self.settings_file = settings_file
        self.persist = persist
        settings, warning = load_settings(settings_file)
        if size:
            settings.window = size
        if projection:
            settings.projection = projection
        if backend:
            settings.backend = backend
        self.state = AppState(settings, cameras, background)
        if warning:
            self.state.message(warning, "error")
        self.frame_count = 0
        self._submitted_moving = False
        self.ui_fps = RateMeter()
        self.closed = False
        self.last_screenshot: Path | None = None
        self._pending_screenshot: Path | None = None
        self.placed: list[Item] = []  # the texts the overlays placed over the panes this frame (ui.text)
        self.part_tops: dict[tuple[int, str], float] = {}  # each pane part's y below its label and message lines
        self.dialogs = FileDialogs(self.state.open)
        self._init_window(visible)
        self.worker = RenderWorker(self.shared, on_result=glfw.post_empty_event)  # a result wakes the event loop
        self.analysis = PaneAnalysis(self.state, self.worker)  # difference and error views, PSNR/SSIM
        self.panes = PaneRenders(self.state, self.worker, self.ctx, self.analysis.visualize)
        self.inspector = Inspector(self.state)  # the pinned pixel's traces
        self.actions = action_table(
            {"window": self, "state": self.state, "analysis": self.analysis, "inspector": self.inspector}
        )
        self.state.open(scene_path or DEFAULT_SCENE)
        if data is not None:
            self.state.dataset.open(data, images)  # its views and photos (app/dataset.py)

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
        w, h = self.state.settings.window
        monitor = glfw.get_primary_monitor()
        mx = my = 0
        if monitor:  # the screen's work area at first; a saved size fitted to it (it may come from a bigger one)
            mx, my, mw, mh = glfw.get_monitor_workarea(monitor)
            if mw > 0 and mh > 0:
                w, h = (mw, mh) if (w, h) == AppSettings().window else (min(w, mw), min(h, mh))
        release_current()  # glfw makes the window's GLX context current: X error if an EGL one is (gb.render on glsl)
        self.window = glfw.create_window(w, h, "gbviewer", None, None)
        if not self.window:
            glfw.terminate()
            _, desc = glfw.get_error()
            desc = desc.decode(errors="replace") if isinstance(desc, bytes) else str(desc or "")
            raise GBViewerError(f"glfw could not create an OpenGL 3.3 window ({desc})")
        if monitor:
            glfw.set_window_pos(self.window, mx, my)
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
        _style()
        addr = ctypes.cast(self.window, ctypes.c_void_p).value
        imgui.backends.glfw_init_for_opengl(addr, True)
        imgui.backends.opengl3_init("#version 330")
        glfw.set_drop_callback(self.window, self._on_drop)
        self.gl_renderer = self.ctx.info.get("GL_RENDERER", "?")
        request, warning = requested_path()
        if warning:
            self.state.message(warning, "error")
        self.shared = SharedContext.open(self.window, self.gl_renderer, request)  # the GPU display path's context
        self.blit_panes = Blitter(self.ctx)  # drawn under the UI
        self.blit_loupe = Blitter(self.ctx)  # drawn over it

    def _on_drop(self, _window, paths) -> None:
        for p in paths:
            self.state.open(p)

    # ---- the frame loop -----------------------------------------------------------------------------------------

    def run(self) -> None:
        try:
            while not glfw.window_should_close(self.window) and not self.closed:
                self.wait_for_events()
                self.step(poll=False)
        finally:
            self.close()

    def wait_for_events(self) -> None:
        """Pace the frame loop: no wait while the camera moves (or flies); while only work in the background goes
        on (renders refining, a load, a video), at most WAITING_FPS frames a second, so that the UI does not take
        the cores the renders need (their threads run at a lower priority); idle, wake on events or every 0.1 s.
        Any event ends a wait at once."""
        s = self.state
        if s.moving or s.fly or self._submitted_moving:  # (the camera just stopped: ask for full frames at once)
            glfw.poll_events()
        elif s.loader is not None or self.worker.busy() or (s.video is not None and not s.video.finished()):
            glfw.wait_events_timeout(1.0 / WAITING_FPS)
        else:
            glfw.wait_events_timeout(0.1)

    def run_frames(self, n: int) -> None:
        for _ in range(n):
            self.step()

    def wait_rendered(self, timeout: float = 120.0) -> bool:
        """Step until the scene is loaded, the camera has stopped and every visible pane shows its latest
        full-resolution request (a small pane renders at full resolution while the camera still moves)."""
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < timeout:
            self.step()
            s = self.state
            if (
                s.loader is None
                and s.scene is not None
                and self.frame_count > 2
                and not s.moving
                and self.panes.all_current()
            ):
                self.step()
                return True
            time.sleep(0.01)
        return False

    def step(self, poll: bool = True) -> None:
        """One UI frame: events, finished loads and renders, the UI, new render requests, draw, swap."""
        if self.closed:
            return
        if poll:
            glfw.poll_events()
        self._poll()
        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        if self.font is not None:
            imgui.push_font(self.font, 16.0)
        io = imgui.get_io()
        scale = (io.display_framebuffer_scale.x or 1.0, io.display_framebuffer_scale.y or 1.0)
        self.state.layout(
            io.display_size.x,
            io.display_size.y,
            imgui.get_frame_height(),
            imgui.get_frame_height() + 6,
            scale,
            dock_side(self),
        )
        self.inspector.follow()
        if self.state.needs_reset:
            self.state.needs_reset = False
            self.state.reset_camera()
            self.state.last_move = 0.0  # framing a scene just opened is no motion: its first pictures go out at once
        handle_input(self)
        draw_menu(self)
        draw_panel(self)
        draw_inspector(self)
        self.panes.queue_images(self.blit_panes)
        overlays.draw_pane_overlays(self)
        draw_analysis_overlays(self)
        overlays.draw_status(self)
        overlays.draw_loupe(self)
        self.state.show_help = draw_help(self.state.show_help)
        self.dialogs.draw_browser()
        if self.font is not None:
            imgui.pop_font()
        imgui.render()
        self.panes.submit()
        self._submitted_moving = self.state.moving  # the requests of this frame were previews
        self._draw(scale)
        glfw.swap_buffers(self.window)
        self.frame_count += 1
        self.ui_fps.tick()

    def _poll(self) -> None:
        """What finished since the last frame: a scene load, renders, a file dialog, a video."""
        first = self.state.scene is None
        opened = self.state.poll_loader()
        if opened is not None:
            glfw.set_window_title(self.window, f"gbviewer - {opened.name}")
            if first:
                self.frame_count = 0
        self.state.poll_dataset()
        self.panes.poll()
        self.analysis.update()
        self.inspector.update()
        self.dialogs.poll()
        self.state.poll_video()

    def _draw(self, scale: tuple[float, float]) -> None:
        """Pane images under the UI, the UI, the loupe's images over it; a queued screenshot of the result."""
        fw, fh = glfw.get_framebuffer_size(self.window)
        self.ctx.screen.use()
        self.ctx.viewport = (0, 0, fw, fh)
        self.ctx.clear(0.07, 0.075, 0.085, 1.0)
        self.blit_panes.flush(fw, fh, scale)
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        self.blit_loupe.flush(fw, fh, scale)
        if self._pending_screenshot is not None:
            path, self._pending_screenshot = self._pending_screenshot, None
            if screenshots.save_window(self.state, self.read_window(), path):
                self.last_screenshot = path

    def close(self) -> None:
        if self.closed:
            return
        self.save_settings()
        self.closed = True
        if self.state.video is not None:
            self.state.video.cancel(wait=10.0)
        self.worker.stop()
        self.analysis.stop()
        self.inspector.stop()
        self.panes.release()
        self.blit_panes.release()
        self.blit_loupe.release()
        self.shared.close()
        imgui.backends.opengl3_shutdown()
        imgui.backends.glfw_shutdown()
        imgui.destroy_context()
        glfw.destroy_window(self.window)
        glfw.terminate()

    def save_settings(self) -> None:
        if not self.persist:
            return
        s = self.state.settings
        try:
            if not glfw.get_window_attrib(self.window, glfw.ICONIFIED):
                s.window = tuple(glfw.get_window_size(self.window))
            s.fov_y_deg = self.state.controller.fov_y_deg
            save_settings(s, self.settings_file)
        except (OSError, GBViewerError) as exc:
            print(f"gbviewer: could not save settings: {exc}")

    # ---- actions that need the window (the others are AppState's) -----------------------------------------------

    def action(self, name: str) -> Callable:
        """The method a key-map action names (`keys.action_table`, built once)."""
        return self.actions[name]

    def open_dialog(self) -> None:
        """The system's file dialog (or the built-in browser) to open a scene or a cameras.json."""
        self.dialogs.open(self.state.scene_path.parent if self.state.scene_path else Path.cwd())

    def escape(self) -> None:
        """Close the help and the built-in browser, leave fly mode, unpin the inspected pixel."""
        self.state.escape()
        self.dialogs.close()
        self.inspector.unpin()

    def quit(self) -> None:
        glfw.set_window_should_close(self.window, True)

    def screenshot_window(self, path: str | Path | None = None) -> Path:
        """Queue a PNG of the whole window (written at the end of this frame, after drawing)."""
        path = Path(path) if path else screenshots.shot_name(self.state, "window")
        self._pending_screenshot = path
        return path

    def screenshot_pane(self, i: int, path: str | Path | None = None, part: str = "a") -> Path | None:
        """What the pane shows (its render, or the photo, a difference...) at its render resolution, 16 bits per
        channel (full precision)."""
        return screenshots.save_pane(self.state, i, path, part, self.analysis.visualize)

    def screenshot_hovered_pane(self) -> None:
        if self.state.hover is not None:
            self.screenshot_pane(self.state.hover[0])

    def read_window(self) -> np.ndarray:
        """The last drawn window contents, (H, W, 3) uint8, row 0 at the top (call right after step())."""
        fw, fh = glfw.get_framebuffer_size(self.window)
        return screenshots.read_framebuffer(self.ctx, fw, fh)


def _style() -> None:
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
