"""The panel's section drawers take the state and the few services they use, never the whole window (read from the
source: importing the panel needs imgui)."""

from __future__ import annotations

import ast
from pathlib import Path

import gbviewer.app

PANEL = Path(gbviewer.app.__file__).resolve().parent / "panel"


def test_section_drawers_take_narrow_handles():
    drawers = 0
    for path in PANEL.glob("*.py"):
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, ast.FunctionDef):
                continue
            hints = {a.arg: ast.unparse(a.annotation) for a in fn.args.args if a.annotation is not None}
            if path.name == "__init__.py":  # draw_panel and sections bind the drawers to the window's parts
                assert list(hints.values()) == ["ViewerApp"], fn.name
                continue
            drawers += 1
            assert "ViewerApp" not in hints.values() and "app" not in hints, f"{path.name}: {fn.name}{hints}"
            assert hints and next(iter(hints.values())) == "AppState", f"{path.name}: {fn.name} takes the state first"
    assert drawers >= 10
