"""The desktop viewer (`gbviewer [SCENE]`). `window` (glfw + imgui-bundle + moderngl; imported only when a window is
opened) composes `state` (scene, panes, settings and the actions on them), `ui/` (key map, input, dialogs, layout,
text placement, blits), `panes` (render requests and textures), `frames/` (what a pane shows, rates, display
paths), `menu`, `panel/` (one module per section), `overlays/` (labels, the difference views' bars) and
`screenshots`. Without a window: `camera/` (control, path, recording), `settings`, `difference/` (the difference,
error and photo views and their thread), `inspector/`, `dataset` (the training dataset's views, the snapped one),
and the threads in `threads/` (renders, scene loading)."""

from __future__ import annotations

import os
from pathlib import Path


def has_display_env(env: dict | None = None) -> tuple[bool, str]:
    """Whether the environment names a display a window could open on: (yes, '') or (no, why)."""
    env = os.environ if env is None else env
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        return False, "no display (neither DISPLAY nor WAYLAND_DISPLAY is set)"
    return True, ""


def open_window(
    scene: str | Path | None = None,
    cameras: str | Path | None = None,
    projection: str | None = None,
    backend: str | None = None,
    data: str | Path | None = None,
    images: str = "images",
    background: tuple[float, float, float] | None = None,
) -> "tuple[bool, str]":
    """Open the viewer and run it until closed: (True, '') or (False, why no window could be opened). `projection`:
    the camera's at the start (default: the saved settings'); `backend`: select it as the panel would (None: the saved
    one); `data`: a training dataset to open beside the scene, its photos in the folder `images`; `background`: the
    panes' background (None: the saved one, or the backdrop of a dataset's opaque photos)."""
    ok, why = has_display_env()
    if not ok:
        return False, why
    from ..core.errors import GBViewerError
    from ..core.extras import require

    for module in ("imgui_bundle", "glfw"):  # imgui_bundle first: it points pyGLFW at its own libglfw
        require("viewer", module, "the viewer")
    require("viewer", "skimage", "the viewer", load=False)  # (imported at the first SSIM)
    from .window import ViewerApp

    try:
        app = ViewerApp(
            scene,
            cameras=cameras,
            projection=projection,
            backend=backend,
            data=data,
            images=images,
            background=background,
        )
    except GBViewerError as exc:
        return False, str(exc)
    app.run()
    return True, ""
