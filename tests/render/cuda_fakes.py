"""Stand-ins for gbviewer._native_cuda's Renderer, for testing the CUDA backend's Python wrapper without a GPU."""

from __future__ import annotations

import threading

import numpy as np

from gbviewer.render import CudaRenderer

TIMEOUT = "CUDA device 0 failed: CUDA error in cudaStreamSynchronize(0): the launch timed out and was terminated"


class FakeDeviceFailed(RuntimeError):
    """Stands in for gbviewer._native_cuda.DeviceFailed."""


class FakeNative:
    """Stands in for gbviewer._native_cuda.Renderer: records calls (at most one at a time), fails the ones it is
    told to once (`fail`: out of device memory) or from then on (`device_fails`: the device failed)."""

    def __init__(self, fail: set[str] = frozenset(), device_fails: set[str] = frozenset()):
        self.fail, self.device_fails, self.calls, self.device = set(fail), set(device_fails), [], 0
        self.busy = threading.Lock()

    def _call(self, name):
        if not self.busy.acquire(blocking=False):
            raise AssertionError(f"{name} entered while another call was running")
        try:
            self.calls.append(name)
            if name in self.fail:
                self.fail.discard(name)
                raise RuntimeError("CUDA out of device memory: could not allocate 1 MiB")
            if name in self.device_fails:
                raise FakeDeviceFailed(TIMEOUT)
        finally:
            self.busy.release()

    def upload(self, *args):
        self._call("upload")

    def upload_weights(self, *args):
        self._call("upload_weights")

    def upload_cells(self, *args):
        self._call("upload_cells")

    def upload_lod(self, *args):
        self._call("upload_lod")

    def upload_cut(self, rows, weights):
        self._call("upload_cut")
        self.cut = (rows.copy(), weights.copy())

    def render(self, *args, view_filter=None, seed=0, frame=0, fast=False, cut=False):
        self._call("render cut" if cut else "render")
        w, h = args[6], args[7]
        return dict(
            rgb=np.zeros((h, w, 3), np.float32),
            alpha=np.zeros((h, w), np.float32),
            evals=np.zeros((h, w), np.int32),
            **STATS,
        )

    def render_to_gl_texture(self, texture, *args, view_filter=None, seed=0, frame=0, fast=False, cut=False):
        self._call("render_to_gl_texture")
        return dict(STATS)

    def release_gl_texture(self, texture):
        self._call(f"release {texture}")

    def release_buffers(self):
        self._call("release_buffers")


STATS = dict(
    preprocess_ms=1.0,
    sort_ms=2.0,
    blend_ms=3.0,
    visible=5,
    sort_length=6,
    pairs=7,
    evaluations=96,
    cells_visible=2,
    cell_misses=1,
)


def fake_renderer(fake: FakeNative) -> CudaRenderer:
    """A CudaRenderer around `fake` instead of a device's renderer."""
    r = object.__new__(CudaRenderer)
    r._attach(fake, FakeDeviceFailed)
    return r
