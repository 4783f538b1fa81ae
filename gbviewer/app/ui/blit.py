"""Pane images drawn into the window with nearest filtering."""

from __future__ import annotations

import moderngl
import numpy as np


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
