"""The key map: one table that drives key handling (`input.handle_keys`), the menus' shortcut hints and the F1 help.

Each row of SHORTCUTS is one line of the help: its label and text, and the keys that trigger actions. An action is
the name of a method of the object its key is `on` (one of OWNERS: `state.AppState`, `window.ViewerApp`,
`difference.views.PaneAnalysis` or `inspector.state.Inspector`), called with the key's `args`; `action_table` resolves
every action once, refusing a key bound twice and an action name given two owners. Rows without keys describe mouse
gestures; keys marked `held` act every frame they are down (fly mode), the others once per press (or repeatedly, with
`repeat`). Key names are the members of `imgui.Key` (kept as text here: no imgui import).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

OWNERS = ("state", "window", "analysis", "inspector")  # what a key's action is a method of
_SYMBOLS = {"left_bracket": "[", "right_bracket": "]", "minus": "-", "equal": "=", "escape": "Esc", "slash": "/"}


@dataclass(frozen=True)
class Key:
    key: str  # an imgui.Key member: "f1", "o", "_0", "left_bracket"...
    action: str
    args: tuple = ()
    on: str = "state"  # one of OWNERS
    shift: bool | None = None  # None: with or without Shift
    ctrl: bool | None = False  # None: with or without Ctrl
    repeat: bool = False  # repeat while held down (else once per press)
    held: bool = False  # act every frame while down, args summed over the held keys

    @property
    def hint(self) -> str:
        """How the key is written in menus and the help: Ctrl+O, F12, Shift+M, ], ?."""
        if self.key == "slash" and self.shift:
            return "?"
        name = _SYMBOLS.get(self.key) or self.key.lstrip("_").upper()
        return ("Ctrl+" if self.ctrl else "") + ("Shift+" if self.shift else "") + name


@dataclass(frozen=True)
class Shortcut:
    label: str  # the help's first column
    text: str  # what it does
    keys: tuple[Key, ...] = ()


SHORTCUTS = (
    Shortcut(
        "F1 or ?",
        "show / hide this help",
        (Key("f1", "toggle_help", ctrl=None), Key("slash", "toggle_help", shift=True, ctrl=None)),
    ),
    Shortcut("Ctrl+O", "open a scene (or a cameras.json)", (Key("o", "open_dialog", ctrl=True, on="window"),)),
    Shortcut("drop a file", "open it (scene or cameras.json)"),
    Shortcut("Left drag", "orbit around the target (fly mode: look around)"),
    Shortcut("Right / middle drag", "pan"),
    Shortcut("Wheel", "dolly towards / away from the target"),
    Shortcut("F", "fly mode on / off", (Key("f", "toggle_fly"),)),
    Shortcut(
        "W A S D",
        "fly forward / left / back / right (fly mode)",
        (
            Key("w", "fly_move", (1, 0, 0), held=True),
            Key("a", "fly_move", (0, -1, 0), held=True),
            Key("s", "fly_move", (-1, 0, 0), held=True),
            Key("d", "fly_move", (0, 1, 0), held=True),
        ),
    ),
    Shortcut(
        "Q E",
        "fly down / up (fly mode)",
        (Key("q", "fly_move", (0, 0, -1), held=True), Key("e", "fly_move", (0, 0, 1), held=True)),
    ),
    Shortcut("Shift", "fly 4x faster"),
    Shortcut("R", "reset the camera to the default framing and field of view", (Key("r", "reset_camera"),)),
    Shortcut(
        "[ ]",
        "previous / next dataset view of the listed split (Dataset panel; after leaving a view: back "
        "to it), else training camera",
        (
            Key("left_bracket", "step_camera", (-1,), repeat=True),
            Key("right_bracket", "step_camera", (1,), repeat=True),
        ),
    ),
    Shortcut("U", "next up axis (-y, +y, +z, -z)", (Key("u", "next_up"),)),
    Shortcut("O", "perspective / orthographic projection", (Key("o", "toggle_projection"),)),
    Shortcut(
        "- =",
        "sampling rate one step down / up (x1/8 .. x8)",
        (Key("minus", "step_rate", (-1,), repeat=True), Key("equal", "step_rate", (1,), repeat=True)),
    ),
    Shortcut("0", "sampling rate x1", (Key("_0", "set_rate", (1.0,)),)),
    Shortcut("1 2 3 4", "number of panes", tuple(Key(f"_{n}", "set_pane_count", (n,)) for n in range(1, 5))),
    Shortcut("G", "panes side by side / 2x2 grid", (Key("g", "toggle_layout"),)),
    Shortcut(
        "M / Shift+M",
        "next / previous mode of the pane under the cursor",
        (Key("m", "next_mode", (1,), shift=False), Key("m", "next_mode", (-1,), shift=True)),
    ),
    Shortcut("V", "split view in the pane under the cursor (drag the line)", (Key("v", "toggle_split"),)),
    Shortcut(
        "X / Shift+X",
        "difference to pane A / error view (difference to the reference) in the pane under the cursor",
        (
            Key("x", "toggle_difference", shift=False, on="analysis"),
            Key("x", "toggle_error", shift=True, on="analysis"),
        ),
    ),
    Shortcut(
        "P / Shift+P",
        "PSNR / SSIM against the reference on the panes / next reference (box, dense, photo)",
        (
            Key("p", "toggle_fidelity", shift=False, on="analysis"),
            Key("p", "next_reference", shift=True, on="analysis"),
        ),
    ),
    Shortcut("L", "magnifier loupe under the cursor", (Key("l", "toggle_loupe"),)),
    Shortcut(
        "T / Ctrl+click",
        "pin the pixel under the cursor in every pane and inspect its traces (T again or Esc unpins)",
        (Key("t", "toggle_pin", on="inspector"),),
    ),
    Shortcut("I", "information overlay on the panes", (Key("i", "toggle_info"),)),
    Shortcut("F12", "screenshot of the window (PNG)", (Key("f12", "screenshot_window", shift=False, on="window"),)),
    Shortcut(
        "Shift+F12",
        "screenshot of the pane under the cursor (16-bit PNG at render resolution)",
        (Key("f12", "screenshot_hovered_pane", shift=True, on="window"),),
    ),
    Shortcut(
        "Esc",
        "close help, leave fly mode, unpin the inspected pixel; else cancel a scene load",
        (Key("escape", "escape", ctrl=None, on="window"),),
    ),
    Shortcut("Ctrl+Q", "quit", (Key("q", "quit", ctrl=True, on="window"),)),
)

KEYS = tuple(k for s in SHORTCUTS for k in s.keys)


def hint(action: str, *args) -> str:
    """The key of `action` (with these args) as menus show it, '' when no key triggers it."""
    return next((k.hint for k in KEYS if k.action == action and k.args == args and not k.held), "")


def label(action: str) -> str:
    """The help's label of the row holding `action` ('F1 or ?' for toggle_help)."""
    return next(s.label for s in SHORTCUTS if any(k.action == action for k in s.keys))


def check_bindings(keys: Sequence[Key] = KEYS) -> None:
    """Raise ValueError for a key bound twice for one Shift/Ctrl combination, an action named on two owners, or an
    owner that is not one of OWNERS."""
    bound: dict[tuple[str, bool, bool], str] = {}
    owner: dict[str, str] = {}
    for k in keys:
        if k.on not in OWNERS:
            raise ValueError(f"key {k.hint}: {k.action} on {k.on!r}, not one of {', '.join(OWNERS)}")
        if owner.setdefault(k.action, k.on) != k.on:
            raise ValueError(f"action {k.action!r} is on both {owner[k.action]} and {k.on}")
        for shift in (False, True) if k.shift is None else (k.shift,):
            for ctrl in (False, True) if k.ctrl is None else (k.ctrl,):
                if (k.key, shift, ctrl) in bound:
                    raise ValueError(f"key {k.hint} is bound to {bound[k.key, shift, ctrl]} and {k.action}")
                bound[k.key, shift, ctrl] = k.action


def action_table(owners: Mapping[str, object], keys: Sequence[Key] = KEYS) -> dict[str, Callable]:
    """{action: the bound method it names on its owner} for every key, after `check_bindings`; `owners` maps each
    of OWNERS to its object."""
    check_bindings(keys)
    table = {}
    for k in keys:
        method = getattr(owners[k.on], k.action, None)
        if not callable(method):
            raise ValueError(f"key {k.hint}: {type(owners[k.on]).__name__} has no action {k.action!r}")
        table[k.action] = method
    return table
