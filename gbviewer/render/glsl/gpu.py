"""The glsl backend's GPU plumbing: storage buffers that grow and are reused, the output texture, compiled compute
programs (cached per context) and their dispatch."""

from __future__ import annotations

import weakref

import numpy as np

from ...core.errors import BackendUnavailable, RenderError
from .context import shader_source

WG = 256  # work-group size of the 1D kernels
MAX_GROUPS = 65535
GROWTH = 1.5

_program_cache: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


class Gpu:
    """Named buffers and programs on one moderngl context. Buffers grow (by GROWTH) when a frame needs more and are
    reused otherwise; `allocations` counts (re)allocations, `uploads` the writes of data from the host (`upload`,
    `upload_after`). `precise_math` selects the shaders' ~1-ulp expf/logf."""

    def __init__(self, ctx, precise_math: bool) -> None:
        self.ctx = ctx
        self.precise_math = bool(precise_math)
        self.allocations = 0
        self.uploads = 0
        self.buffers: dict[str, object] = {}
        self.texture = None
        self.max_block = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 1 << 27)

    def release(self) -> None:
        """Free the buffers and the output texture."""
        for buf in self.buffers.values():
            buf.release()
        self.buffers.clear()
        if self.texture is not None:
            self.texture.release()
            self.texture = None

    # ---- buffers -------------------------------------------------------------------------------------------------

    def _check_size(self, nbytes: int, what: str) -> None:
        if nbytes > self.max_block:
            raise RenderError(
                f"glsl backend: {what} needs {nbytes / 2**20:.0f} MiB in one storage buffer, more than this GPU's "
                f"limit of {self.max_block / 2**20:.0f} MiB (GL_MAX_SHADER_STORAGE_BLOCK_SIZE, "
                f"{self.ctx.info.get('GL_RENDERER', '?')}); render a smaller scene or image, or use backend='cpu'"
            )

    def _allocated(self, obj, what: str, nbytes: int):
        err = self.ctx.error
        if err == "GL_OUT_OF_MEMORY":
            obj.release()
            raise RenderError(f"glsl backend: out of GPU memory allocating {nbytes / 2**20:.0f} MiB for {what}")
        self.allocations += 1
        return obj

    def ensure(self, name: str, nbytes: int, what: str = ""):
        """Buffer `name` with at least `nbytes` (grown by GROWTH, never shrunk)."""
        nbytes = max(int(nbytes), 16)
        buf = self.buffers.get(name)
        if buf is not None and buf.size >= nbytes:
            return buf
        what = what or name
        self._check_size(nbytes, what)
        size = nbytes if buf is None else min(max(nbytes, int(buf.size * GROWTH)), self.max_block)
        size = (size + 255) // 256 * 256
        if buf is not None:
            buf.release()
            del self.buffers[name]
        self.ctx.error  # noqa: B018 - clear a stale error flag before checking ours
        buf = self._allocated(self.ctx.buffer(reserve=size), what, size)
        self.buffers[name] = buf
        return buf

    def upload(self, name: str, data: np.ndarray, what: str) -> None:
        self.ensure(name, data.nbytes, what).write(data.tobytes())
        self.uploads += 1

    def upload_after(self, name: str, keep: int, data: np.ndarray, what: str) -> None:
        """Write `data` into buffer `name` after its first `keep` bytes (which it holds), which stay (copied on the
        GPU into the new buffer where it grows)."""
        old = self.buffers.pop(name, None)
        if old is not None and old.size >= keep + data.nbytes:
            self.buffers[name] = old
        else:
            try:
                new = self.ensure(name, keep + data.nbytes, what)
                if keep:
                    self.ctx.copy_buffer(new, old, keep)
            finally:
                if old is not None:
                    old.release()
        self.buffers[name].write(data.tobytes(), offset=keep)
        self.uploads += 1

    def ensure_texture(self, W: int, H: int):
        """The RGBA32F output image of W x H (row 0: the image top)."""
        tex = self.texture
        if tex is not None and tex.size == (W, H):
            return tex
        if tex is not None:
            tex.release()
        self.ctx.error  # noqa: B018
        tex = self._allocated(self.ctx.texture((W, H), 4, dtype="f4"), "the output image", W * H * 16)
        import moderngl

        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture = tex
        return tex

    # ---- programs ------------------------------------------------------------------------------------------------

    def program(self, name: str, **defines):
        """shaders/`name` compiled with `defines` (cached per context)."""
        defines.setdefault("GBV_PRECISE_MATH", int(self.precise_math))
        key = (name, tuple(sorted(defines.items())))
        cache = _program_cache.setdefault(self.ctx, {})
        prog = cache.get(key)
        if prog is None:
            src = shader_source(name, defines)
            try:
                prog = self.ctx.compute_shader(src)
            except Exception as exc:  # noqa: BLE001 - moderngl raises its Error with the compiler log
                raise BackendUnavailable(
                    f"glsl backend: {name} does not compile on {self.ctx.info.get('GL_RENDERER', '?')}: {exc}"
                ) from None
            cache[key] = prog
        return prog

    @staticmethod
    def set(prog, **uniforms) -> None:
        for k, v in uniforms.items():
            u = prog.get(k, None)
            if u is None:
                continue  # optimised out
            if isinstance(v, np.ndarray):
                u.write(v.tobytes())
            else:
                u.value = v

    def dispatch(self, prog, groups: int, *bindings) -> None:
        """Bind `bindings` to storage slots 0.. and run `groups` work groups (split over x and y)."""
        for i, buf in enumerate(bindings):
            buf.bind_to_storage_buffer(i)
        if groups <= 0:
            return
        gx = min(groups, MAX_GROUPS)
        prog.run(gx, -(-groups // gx), 1)
        self.ctx.memory_barrier()

    def run(self, name: str, groups: int, bindings: tuple, **uniforms) -> None:
        """Program `name` with `uniforms` set, dispatched over `groups` work groups with `bindings`."""
        prog = self.program(name)
        self.set(prog, **uniforms)
        self.dispatch(prog, groups, *bindings)
