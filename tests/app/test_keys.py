"""The key map: every key has an action, and the help, the menus and the panel's hints all come from the table."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest

from gbviewer.app import keys
from gbviewer.app.difference_views import PaneAnalysis
from gbviewer.app.inspector import Inspector
from gbviewer.app.state import AppState

APP = Path(keys.__file__).resolve().parent


def window_actions() -> set[str]:
    """Public methods of ViewerApp (read from its source: importing window needs imgui and glfw)."""
    import ast

    tree = ast.parse((APP / "window.py").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "ViewerApp")
    return {f.name for f in cls.body if isinstance(f, ast.FunctionDef) and not f.name.startswith("_")}


def test_every_key_names_an_action_that_takes_its_args():
    windowed = window_actions()
    for k in keys.KEYS:
        method = (getattr(AppState, k.action, None) or getattr(PaneAnalysis, k.action, None)
                  or getattr(Inspector, k.action, None))
        if method is None:
            assert k.action in windowed, f"{k.key}: no action {k.action!r}"
            continue
        params = list(inspect.signature(method).parameters.values())[1:]
        extra = (1, 2) if k.held else (0, 0)  # held keys also get the frame time and Shift
        required = [p for p in params if p.default is inspect.Parameter.empty]
        assert len(required) <= len(k.args) + extra[1] <= len(params), f"{k.key}: {k.action}{k.args}"


def test_keys_are_unique_per_modifier_combination():
    seen = set()
    for k in keys.KEYS:
        for shift in ((False, True) if k.shift is None else (k.shift,)):
            for ctrl in ((False, True) if k.ctrl is None else (k.ctrl,)):
                assert (k.key, shift, ctrl) not in seen, f"{k.key} is bound twice"
                seen.add((k.key, shift, ctrl))


def test_each_help_row_names_its_keys():
    for s in keys.SHORTCUTS:
        for k in s.keys:
            assert k.hint in s.label.replace("/", " ").split() or k.hint == s.label, (k.hint, s.label)


@pytest.mark.parametrize("action,args,text", [("open_dialog", (), "Ctrl+O"), ("quit", (), "Ctrl+Q"),
                                              ("screenshot_window", (), "F12"), ("set_pane_count", (3,), "3"),
                                              ("step_camera", (1,), "]"), ("step_camera", (-1,), "["),
                                              ("toggle_help", (), "F1"), ("next_mode", (-1,), "Shift+M"),
                                              ("fly_move", (1, 0, 0), ""), ("open", (), "")])
def test_menu_hints(action, args, text):
    assert keys.hint(action, *args) == text


def test_help_covers_the_keys_the_issue_names():
    labels = " ".join(s.label for s in keys.SHORTCUTS)
    for k in ("F1", "?", "W A S D", "Q E", "R", "[ ]", "F12", "L", "V", "- =", "1 2 3 4", "Ctrl+O"):
        assert k in labels
    assert keys.label("toggle_help") == "F1 or ?"


def test_menus_help_and_panel_take_key_names_from_the_table():
    """No key name is spelled out in the UI code: menu hints go through keys.hint, the help lists SHORTCUTS."""
    for path in [APP / "menu.py", APP / "dialogs.py", *(APP / "panel").glob("*.py")]:
        src = path.read_text()
        for text in ('"Ctrl+', '"F12"', '"F1"', "(R)", "(F)", "(U)", "(L)", "(F12)"):
            assert text not in src, f"{path.name} spells out {text}"
    assert "SHORTCUTS" in (APP / "dialogs.py").read_text() and "hint(" in (APP / "menu.py").read_text()
