"""Screenshots: a PNG of the window (as drawn) and a 16-bit PNG of a pane's render at its render resolution."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..core.files import atomic_write
from .frames.views import encode_png16, visualize
from .settings import PANE_NAMES

if TYPE_CHECKING:
    from ..render import Frame
    from .state import AppState

Colour = Callable[[tuple[int, str], "Frame", str], tuple[np.ndarray, str]]  # slot, frame, view -> image, legend


def shot_dir(state: AppState) -> Path:
    return Path(state.settings.screenshot_dir or Path.cwd() / "screenshots").expanduser()


def shot_name(state: AppState, what: str, suffix: str = ".png") -> Path:
    """A new file in the screenshot folder: <scene>-<what>-<date>-<time>[-k]<suffix>."""
    stem = state.scene_path.stem if state.scene_path else "gbviewer"
    base = shot_dir(state) / f"{stem}-{what}-{time.strftime('%Y%m%d-%H%M%S')}"
    path, k = base.parent / f"{base.name}{suffix}", 1
    while path.exists():
        k += 1
        path = base.parent / f"{base.name}-{k}{suffix}"
    return path


def read_framebuffer(ctx, width: int, height: int) -> np.ndarray:
    """The window's framebuffer, (H, W, 3) uint8, row 0 at the top."""
    ctx.screen.use()
    data = ctx.screen.read(viewport=(0, 0, width, height), components=3, alignment=1)
    return np.frombuffer(data, np.uint8).reshape(height, width, 3)[::-1].copy()


def save_window(state: AppState, img: np.ndarray, path: Path) -> bool:
    """Write the window image as a PNG, saying so (or why not) in the status bar."""
    from PIL import Image

    try:
        atomic_write(path, lambda p: Image.fromarray(img).save(p, format="PNG"), force=True)
    except OSError as exc:
        state.message(f"screenshot failed: {exc}", "error")
        return False
    state.message(f"saved {path}")
    return True


def save_pane(
    state: AppState, i: int, path: str | Path | None = None, part: str = "a", colour: Colour | None = None
) -> Path | None:
    """What the pane part shows (its render, a debug view, a difference or the photo: `colour`, the window's
    `PaneAnalysis.visualize`; default the plain views) at its render resolution, 16 bits per channel."""
    shown = state.panes[i].parts[part]
    if shown.frame is None:
        state.message(f"pane {PANE_NAMES[i]} has no image yet", "warn")
        return None
    view = shown.view or "color"
    rgb, _ = colour((i, part), shown.frame, view) if colour is not None else visualize(shown.frame, view)
    path = Path(path) if path else shot_name(state, f"pane{PANE_NAMES[i]}")
    data = encode_png16(rgb)
    try:
        atomic_write(path, lambda p: p.write_bytes(data), force=True)
    except OSError as exc:
        state.message(f"screenshot failed: {exc}", "error")
        return None
    state.message(f"saved {path}")
    return path
