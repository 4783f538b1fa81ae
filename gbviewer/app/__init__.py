"""The desktop viewer (`gbviewer [SCENE]`): `logic` (pure, unit-tested), `worker` (render and load threads),
`window` (glfw + imgui-bundle + moderngl; imported only when a window is opened)."""

from __future__ import annotations

from pathlib import Path

from .logic import has_display_env


def open_window(scene: str | Path | None = None, cameras: str | Path | None = None) -> "tuple[bool, str]":
    """Open the viewer and run it until closed: (True, '') or (False, why no window could be opened)."""
    ok, why = has_display_env()
    if not ok:
        return False, why
    try:
        from .window import ViewerApp
    except ImportError as exc:  # glfw, imgui-bundle or moderngl missing
        return False, f"the window needs glfw, imgui-bundle and moderngl ({exc})"
    from ..errors import GBViewerError

    try:
        app = ViewerApp(scene, cameras=cameras)
    except GBViewerError as exc:
        return False, str(exc)
    app.run()
    return True, ""
