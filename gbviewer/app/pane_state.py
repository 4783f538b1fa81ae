"""What each pane holds: its place and render size, what each of its parts shows (the last finished frame, or why
there is none), the requests in flight, frame rates."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..render import Frame
from .frames.accumulate import Accumulation
from .frames.rates import PREVIEW_LOD_PX
from .settings import PANE_NAMES
from .threads.worker import RenderJob
from .ui.layout import Rect


class RateMeter:
    """Events per second over the last `span` seconds."""

    def __init__(self, span: float = 2.0) -> None:
        self.span = span
        self.times: deque[float] = deque()

    def tick(self, t: float | None = None) -> None:
        t = time.perf_counter() if t is None else t
        self.times.append(t)
        while self.times and self.times[0] < t - self.span:
            self.times.popleft()

    def rate(self, now: float | None = None) -> float:
        now = time.perf_counter() if now is None else now
        ts = [t for t in self.times if t >= now - self.span]
        if len(ts) < 2:
            return 0.0
        return (len(ts) - 1) / max(1e-9, ts[-1] - ts[0])


@dataclass(frozen=True)
class PaneError:
    """Why a pane part shows no new image: its render failed ("render"), or its request was refused before rendering
    ("too_large": over MAX_SAMPLES; cleared by the next request of the part that fits)."""

    kind: Literal["render", "too_large"]
    text: str


@dataclass(eq=False)
class Shown:
    """What one pane part (its whole image, or one side of a split) shows: the last finished frame."""

    texture: object = None
    frame: Frame | None = None
    job: RenderJob | None = None
    view: str = ""
    legend: str = ""
    image: np.ndarray | None = None  # uint8 (H, W, 3) as uploaded
    error: PaneError | None = None  # why its last request has no image
    progress: float | None = None  # fraction of a refining frame's tiles on screen; None once final
    stage: str = ""  # what is on screen: "preview", "quick" (x1 sample), "refining", "final"
    pacing: dict[str, float] = field(default_factory=dict)  # ms from a request to its "preview"/"tiles"/"final"
    accumulation: Accumulation = field(default_factory=Accumulation)  # a stochastic mode's frames so far


@dataclass
class PaneState:
    """One pane: where it is, its render size, what it shows and the requests it has in flight."""

    index: int
    parts: dict[str, Shown] = field(default_factory=lambda: {"a": Shown(), "b": Shown()})
    submitted: dict = field(default_factory=dict)  # part -> key of the last request
    asked: dict = field(default_factory=dict)  # part -> the last request (RenderJob: what it waits for)
    fps: dict[str, RateMeter] = field(default_factory=lambda: {"a": RateMeter(), "b": RateMeter()})
    ms_per_px: dict = field(default_factory=dict)  # (part, mode, supersample, backend) -> cost of a full render
    rect: Rect = Rect(0, 0, 1, 1)
    render_size: tuple[int, int] = (1, 1)  # at the current rate, without a preview drop
    preview_lod: float = PREVIEW_LOD_PX  # the LOD cut of its previews (rates.preview_lod adapts it)

    @property
    def name(self) -> str:
        return PANE_NAMES[self.index]

    def forget(self, preview_lod: float = PREVIEW_LOD_PX) -> None:
        """Drop what belongs to the previous scene: its frames, requests and measured costs; the next scene's previews
        start at `preview_lod` (rates.first_preview_lod)."""
        self.parts = {"a": Shown(), "b": Shown()}
        self.submitted.clear()
        self.asked.clear()
        self.ms_per_px.clear()
        self.preview_lod = preview_lod
