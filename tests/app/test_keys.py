"""The key map: every key has an action on its one owner (resolved once, duplicates refused), and the help, the
menus and the panel's hints all come from the table."""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from gbviewer.app.difference.views import PaneAnalysis
from gbviewer.app.inspector.state import Inspector
from gbviewer.app.state import AppState
from gbviewer.app.ui import keys

APP = Path(keys.__file__).resolve().parents[1]  # gbviewer/app


def window_actions() -> set[str]:
    """Public methods of ViewerApp (read from its source: importing window needs imgui and glfw)."""
    import ast

    tree = ast.parse((APP / "window.py").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "ViewerApp")
    return {f.name for f in cls.body if isinstance(f, ast.FunctionDef) and not f.name.startswith("_")}


OWNER_CLASSES = {"state": AppState, "analysis": PaneAnalysis, "inspector": Inspector}  # and "window": ViewerApp


def test_every_key_names_an_action_of_its_owner_that_takes_its_args():
    windowed = window_actions()
    for k in keys.KEYS:
        if k.on == "window":
            assert k.action in windowed, f"{k.key}: ViewerApp has no action {k.action!r}"
            continue
        method = getattr(OWNER_CLASSES[k.on], k.action, None)
        assert callable(method), f"{k.key}: {k.on} has no action {k.action!r}"
        params = list(inspect.signature(method).parameters.values())[1:]
        extra = (1, 2) if k.held else (0, 0)  # held keys also get the frame time and Shift
        required = [p for p in params if p.default is inspect.Parameter.empty]
        assert len(required) <= len(k.args) + extra[1] <= len(params), f"{k.key}: {k.action}{k.args}"


def owners(missing: str = "") -> dict[str, SimpleNamespace]:
    """Stand-ins for the four owners, each with a method per action of its keys (but `missing`)."""
    return {
        o: SimpleNamespace(**{k.action: (lambda *a, o=o: o) for k in keys.KEYS if k.on == o and k.action != missing})
        for o in keys.OWNERS
    }


def test_the_action_table_resolves_each_action_on_its_one_owner():
    table = keys.action_table(owners())
    assert set(table) == {k.action for k in keys.KEYS}
    assert table["escape"]() == "window" and table["toggle_pin"]() == "inspector"  # AppState has escape too
    assert table["toggle_error"]() == "analysis" and table["reset_camera"]() == "state"
    with pytest.raises(ValueError, match="has no action 'toggle_fly'"):
        keys.action_table(owners(missing="toggle_fly"))


@pytest.mark.parametrize(
    "extra, message",
    [
        (keys.Key("f1", "toggle_info"), "key F1 is bound to toggle_help and toggle_info"),  # F1 with any Ctrl
        (keys.Key("m", "toggle_info", shift=None), "key M is bound to next_mode and toggle_info"),
        (keys.Key("f2", "escape"), "action 'escape' is on both window and state"),
        (keys.Key("f2", "toggle_loupe", on="panel"), "toggle_loupe on 'panel', not one of"),
    ],
)
def test_a_duplicate_binding_or_action_name_fails(extra, message):
    keys.check_bindings()  # the real table passes
    with pytest.raises(ValueError, match=re.escape(message)):
        keys.action_table(owners(), keys.KEYS + (extra,))


def test_each_help_row_names_its_keys():
    for s in keys.SHORTCUTS:
        for k in s.keys:
            assert k.hint in s.label.replace("/", " ").split() or k.hint == s.label, (k.hint, s.label)


@pytest.mark.parametrize(
    "action,args,text",
    [
        ("open_dialog", (), "Ctrl+O"),
        ("quit", (), "Ctrl+Q"),
        ("screenshot_window", (), "F12"),
        ("set_pane_count", (3,), "3"),
        ("step_camera", (1,), "]"),
        ("step_camera", (-1,), "["),
        ("toggle_help", (), "F1"),
        ("next_mode", (-1,), "Shift+M"),
        ("fly_move", (1, 0, 0), ""),
        ("open", (), ""),
    ],
)
def test_menu_hints(action, args, text):
    assert keys.hint(action, *args) == text


def test_help_covers_the_keys_the_issue_names():
    labels = " ".join(s.label for s in keys.SHORTCUTS)
    for k in ("F1", "?", "W A S D", "Q E", "R", "[ ]", "F12", "L", "V", "- =", "1 2 3 4", "Ctrl+O"):
        assert k in labels
    assert keys.label("toggle_help") == "F1 or ?"


def test_menus_help_and_panel_take_key_names_from_the_table():
    """No key name is spelled out in the UI code: menu hints go through keys.hint, the help lists SHORTCUTS."""
    for path in [APP / "menu.py", APP / "ui" / "dialogs.py", *(APP / "panel").glob("*.py")]:
        src = path.read_text()
        for text in ('"Ctrl+', '"F12"', '"F1"', "(R)", "(F)", "(U)", "(L)", "(F12)"):
            assert text not in src, f"{path.name} spells out {text}"
    assert "SHORTCUTS" in (APP / "ui" / "dialogs.py").read_text() and "hint(" in (APP / "menu.py").read_text()
