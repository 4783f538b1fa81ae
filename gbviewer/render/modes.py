"""The blending modes (Mode, gbv::Mode's values) and the constants that group them. Imports nothing of the render
layer, so that every module of it (spec, types, the backends) can name a mode."""

from __future__ import annotations

import enum

from ..core.errors import RenderError


class Mode(enum.IntEnum):
    """Blending modes; values match `gbv::Mode` in native/include/gbv/common.h."""

    SCALAR = 0  # 3DGS: alpha at the pixel centre, +0.3 px^2 dilation
    MIP = 1  # Mip-Splatting 2D filter (0.1 px^2 with opacity compensation)
    ANALYTIC = 2  # Analytic-Splatting: alpha integrated over the pixel, scalar transmittance
    GAUSSIAN_BLENDING = 3  # spatial transmittance window (Gaussian Blending)
    WSR = 4  # sort-free weighted sum (LC-WSR, Hou et al.): order independent, no sort
    DUPLEX = 5  # Duplex-GS: cells sorted, weighted sum inside a cell, cell transmittance and early termination
    STOCHASTIC = 6  # stochastic transparency (StochasticSplats ST): fragments kept with probability alpha, opaque
    STOCHASTIC_POPFREE = 7  # its pop-free variant (ST-popfree): depth-tested on each splat's per-pixel depth plane
    EVAL3D = 8  # 3DGUT: each splat at its maximum along the pixel's ray, per pixel in that depth's order
    STOPTHEPOP = 9  # StopThePop: 3DGS's 2D splats by depth along the ray: tile, 4x4, 2x2 and K-entry pixel queues

    @classmethod
    def parse(cls, value: "str | int | Mode") -> "Mode":
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            try:
                return cls[value.strip().upper().replace("-", "_")]
            except KeyError:
                names = ", ".join(m.name.lower() for m in cls)
                raise RenderError(f"unknown mode {value!r}; expected one of {names}") from None
        try:
            return cls(int(value))
        except ValueError:
            raise RenderError(f"unknown mode {value!r}") from None

    @property
    def label(self) -> str:
        return self.name.lower()


ORDER_INDEPENDENT = (Mode.WSR, Mode.DUPLEX)
STOCHASTIC_MODES = (Mode.STOCHASTIC, Mode.STOCHASTIC_POPFREE)  # another frame index, another sample
PER_PIXEL_SORTED = (Mode.EVAL3D, Mode.STOPTHEPOP)  # each pixel in its own order (gbv::per_pixel_sorted)
STOPTHEPOP_QUEUE = 4  # StopThePop's published per-pixel queue (gbv::STOPTHEPOP_QUEUE)
MAX_QUEUE = 64  # the longest per-pixel queue (0: unbounded, the exact per-pixel sort)
MAX_SEED = 2**32 - 1  # the stochastic modes' seed and frame index are uint32 (gbv/stochastic.h)
