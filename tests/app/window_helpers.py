"""What the window tests share: screenshots through the app, pane pixels, the expected pane image, key presses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import gbviewer as gb
from gbviewer.app.frames.views import visualize
from gbviewer.outputs.figure import to_uint8, upscale_nearest

OUTPUT = Path(__file__).resolve().parents[1] / "output"
GBVIEWER_ROOT = str(Path(gb.__file__).resolve().parents[1])  # subprocesses import the gbviewer under test
LABEL_BAND = 60  # pixels at the top of a pane that hold the label and the preview/rendering line


def shot(app, name: str) -> np.ndarray:
    """A screenshot through the app's own function, kept in tests/output/."""
    OUTPUT.mkdir(exist_ok=True)
    path = app.screenshot_window(OUTPUT / f"{name}.png")
    app.step()
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"))


def pane_pixels(img: np.ndarray, rect) -> np.ndarray:
    return img[rect.y : rect.y + rect.h, rect.x : rect.x + rect.w]


def expected_pane(app, i: int, part: str = "a", view: str = "color") -> np.ndarray:
    """gb.render at the pane's render camera on the CPU (whatever the pane rendered on: the backends agree far within
    one level, and a glsl render here, in the thread of the window's context, would need the headless context made
    current beside it), nearest-upscaled to the pane."""
    p = app.state.panes[i]
    job = p.parts[part].job
    frame = gb.render(
        app.state.scene, job.camera, job.settings.mode, job.settings.supersample, "cpu", debug=job.settings.debug
    )
    rgb, _ = visualize(frame, view)
    return upscale_nearest(to_uint8(rgb), p.rect.h, p.rect.w)


def agree(a: np.ndarray, b: np.ndarray, border: int = 1) -> float:
    """Fraction of pixels equal within 1 level, `border` pixels in from the edges (the hovered pane's outline)."""
    if border:
        a, b = a[:-border, border:-border], b[:-border, border:-border]
    return float((np.abs(a.astype(int) - b.astype(int)).max(axis=2) <= 1).mean())


def wait(app):
    assert app.wait_rendered(180), "the panes did not finish rendering"


def press(app, key, shift: bool = False, frames: int = 1) -> None:
    from imgui_bundle import imgui

    io = imgui.get_io()
    if shift:
        io.add_key_event(imgui.Key.left_shift, True)
        io.add_key_event(imgui.Key.mod_shift, True)
    io.add_key_event(key, True)
    app.run_frames(frames)
    io.add_key_event(key, False)
    if shift:
        io.add_key_event(imgui.Key.left_shift, False)
        io.add_key_event(imgui.Key.mod_shift, False)
    app.step()
