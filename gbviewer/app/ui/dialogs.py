"""Dialogs: the system's file and folder dialogs (through zenity, kdialog... via portable-file-dialogs) or a built-in
file browser where none exists, and the F1 help window listing `keys.SHORTCUTS`."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Callable

from imgui_bundle import imgui

from .keys import SHORTCUTS, label

SCENE_EXTS = (".ply", ".splat", ".spz", ".sog", ".json", ".pth")
DIALOG_PROGRAMS = ("zenity", "kdialog", "qarma", "matedialog", "yad")


class FileDialogs:
    """Asks for a scene or cameras.json to open and hands the choice to `open_fn` (or for a folder, handed to the
    function `open_folder` names), never blocking the UI."""

    def __init__(self, open_fn: Callable[[Path | str], None]) -> None:
        self.open_fn = open_fn
        self.file_dialog = None  # portable_file_dialogs.open_file while it is shown
        self.folder_dialog: tuple | None = None  # (portable_file_dialogs.select_folder, its function) while shown
        self.browser: dict | None = None  # the built-in browser's folder, filter and (choosing folders) function

    def open(self, start: Path) -> None:
        """The system's file dialog when a dialog program exists, else the built-in browser, starting in `start`."""
        if any(shutil.which(p) for p in DIALOG_PROGRAMS):
            from imgui_bundle import portable_file_dialogs as pfd

            filters = ["Splat scenes", "*.ply *.splat *.spz *.sog *.json", "All files", "*"]
            self.file_dialog = pfd.open_file("Open a scene or cameras.json", str(start), filters)
        else:
            self.browser = {"dir": Path(start), "filter": ""}

    def open_folder(self, start: Path, title: str, pick: Callable[[Path], None]) -> None:
        """The system's folder dialog (or the built-in browser, choosing a folder) starting in `start`; the folder
        chosen goes to `pick`."""
        if any(shutil.which(p) for p in DIALOG_PROGRAMS):
            from imgui_bundle import portable_file_dialogs as pfd

            self.folder_dialog = (pfd.select_folder(title, str(start)), pick)
        else:
            self.browser = {"dir": Path(start), "filter": "", "pick": pick, "title": title}

    def close(self) -> None:
        self.browser = None

    def poll(self) -> None:
        """Open what the system dialogs returned, once they have."""
        if self.file_dialog is not None and self.file_dialog.ready(0):
            result = self.file_dialog.result()
            self.file_dialog = None
            for p in result or []:
                self.open_fn(p)
        if self.folder_dialog is not None and self.folder_dialog[0].ready(0):
            (dialog, pick), self.folder_dialog = self.folder_dialog, None
            if dialog.result():
                pick(Path(dialog.result()))

    def _choose(self, path: Path) -> None:
        pick = self.browser.get("pick") or self.open_fn
        self.browser = None
        pick(path)

    def draw_browser(self) -> None:
        """A small built-in file browser, for machines without a system file dialog program."""
        b = self.browser
        if b is None:
            return
        io = imgui.get_io()
        imgui.set_next_window_pos(
            (io.display_size.x / 2, io.display_size.y / 2), imgui.Cond_.appearing.value, (0.5, 0.5)
        )
        imgui.set_next_window_size((620, 460), imgui.Cond_.appearing.value)
        folders = b.get("pick") is not None  # choosing a folder
        opened, keep = imgui.begin(
            b.get("title", "Open a scene or cameras.json"), True, imgui.WindowFlags_.no_collapse.value
        )
        if opened:
            d: Path = b["dir"]
            if imgui.button("Up"):
                b["dir"] = d.parent
            imgui.same_line()
            imgui.set_next_item_width(-1)
            ch, typed = imgui.input_text("##dir", str(d), imgui.InputTextFlags_.enter_returns_true.value)
            if ch:
                t = Path(typed).expanduser()
                if t.is_dir():
                    b["dir"] = t
                elif t.exists() and not folders:
                    self._choose(t)
            imgui.begin_child("files", (0, -32))
            try:
                entries = sorted(d.iterdir(), key=lambda e: (not e.is_dir(), e.name.lower()))
            except OSError as exc:
                entries = []
                imgui.text_colored(imgui.ImVec4(1, 0.45, 0.4, 1), str(exc))
            for e in entries:
                if e.name.startswith("."):
                    continue
                is_dir = e.is_dir()
                if not is_dir and (folders or e.suffix.lower() not in SCENE_EXTS):
                    continue
                if imgui.selectable(f"[{e.name}]" if is_dir else e.name, False)[0]:
                    if is_dir and (folders or not (e / "meta.json").exists()):  # a folder to enter, not a SOG scene
                        b["dir"] = e
                    else:
                        self._choose(e)
                        break
            imgui.end_child()
            if not folders:
                imgui.text_disabled("click a file to open it; a folder with meta.json opens as a SOG scene")
            elif imgui.button(f"Open {d.name or d}"):
                self._choose(d)
        imgui.end()
        if not keep:
            self.browser = None


def draw_help(shown: bool) -> bool:
    """The keyboard and mouse help (from keys.SHORTCUTS) while `shown`; False once its close button is clicked."""
    if not shown:
        return False
    io = imgui.get_io()
    w = min(720, io.display_size.x - 24)  # fits the window; long actions wrap, a short window scrolls
    h = min(44 + 25 * len(SHORTCUTS), io.display_size.y - 24)
    imgui.set_next_window_pos((io.display_size.x / 2, io.display_size.y / 2), 0, (0.5, 0.5))
    imgui.set_next_window_size((w, h))
    imgui.set_next_window_bg_alpha(0.98)
    flags = (
        imgui.WindowFlags_.no_resize
        | imgui.WindowFlags_.no_collapse
        | imgui.WindowFlags_.no_saved_settings
        | imgui.WindowFlags_.no_move
    ).value
    opened, keep = imgui.begin(f"Keyboard and mouse ({label('toggle_help')} to close)", True, flags)
    if opened and imgui.begin_table("keys", 2, imgui.TableFlags_.row_bg.value):
        imgui.table_setup_column("key", imgui.TableColumnFlags_.width_fixed.value, 170)
        imgui.table_setup_column("action")
        for s in SHORTCUTS:
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text_colored(imgui.ImVec4(0.5, 0.75, 1.0, 1.0), s.label)
            imgui.table_next_column()
            imgui.text_wrapped(s.text)
        imgui.end_table()
    imgui.end()
    return keep
