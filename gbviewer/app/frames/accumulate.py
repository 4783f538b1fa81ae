"""Progressive sampling of the stochastic modes in the viewer: while the camera is still, each finished frame of a
stochastic pane part is followed by a request for the next frame index (`RenderSettings.frame`, another independent
sample), and the part shows the running mean of its frames, the samples per pixel on its label; a moving camera
renders frame 0 alone (one sample per pixel without supersampling), as the web viewers do: Spark's
`SparkViewpoint.stochastic` averages frames over time (sparkjsdev/spark PR #135), PlayCanvas's
`GSplatParams.stochastic` shows each frame's dithered samples (playcanvas/engine PR #9443)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...render import Frame, RenderSettings
from ...render.modes import STOCHASTIC_MODES

MAX_FRAMES = 256  # a still pane stops sampling here


def is_stochastic(settings: RenderSettings) -> bool:
    return settings.mode in STOCHASTIC_MODES


@dataclass
class Accumulation:
    """One pane part's running sum of the frames of one request (`key`: the request without its frame index)."""

    key: tuple | None = None
    frames: int = 0
    rgb: np.ndarray | None = None  # float64 sums
    alpha: np.ndarray | None = None

    def request(self, key: tuple, settings: RenderSettings, moving: bool) -> RenderSettings | None:
        """The settings to request for `key`: frame 0 while moving or for another key, else the next frame index;
        None once MAX_FRAMES frames are summed (nothing left to request)."""
        if moving or key != self.key:
            return replace(settings, frame=0)
        if self.frames >= MAX_FRAMES:
            return None
        return replace(settings, frame=self.frames)

    def add(self, key: tuple, frame: Frame, index: int) -> Frame:
        """The running mean after a finished frame of `key` with frame index `index`; another key, or an index that
        is not the next one, starts the sum again."""
        if key != self.key or index != self.frames or self.rgb is None or self.rgb.shape != frame.rgb.shape:
            self.key, self.frames = key, 0
            self.rgb, self.alpha = np.zeros(frame.rgb.shape), np.zeros(frame.alpha.shape)
        self.rgb += frame.rgb
        self.alpha += frame.alpha
        self.frames += 1
        return Frame(
            (self.rgb / self.frames).astype(np.float32),
            (self.alpha / self.frames).astype(np.float32),
            frame.stats,
            frame.debug,
        )

    def samples(self, supersample: int) -> int:
        """Samples per pixel of the mean on screen."""
        return max(1, self.frames) * supersample**2
