"""The Backend panel's SIMD line: what gb.build_info() reports, the compiler line as its tooltip, in the
warning colour when the blend runs scalar. Drawn against a recording stand-in for imgui (no window needed)."""

from __future__ import annotations

from types import SimpleNamespace
from unittest import mock

import pytest

pytest.importorskip("imgui_bundle", reason="the viewer extra (imgui-bundle) is not installed")

from gbviewer.app.panel import backend
from gbviewer.render import build_info, compiler_line, simd_line


def draw(monkeypatch, info: dict) -> mock.MagicMock:
    """Draw the section with `info` as the build report; the recorded imgui calls."""
    imgui = mock.MagicMock()
    imgui.radio_button.return_value = False
    imgui.is_item_hovered.return_value = True
    monkeypatch.setattr(backend, "imgui", imgui)
    monkeypatch.setattr(backend, "build_info", lambda: info)
    worker = SimpleNamespace(
        backend_status=lambda name: (True, ""),
        backend_for=lambda name: "cpu",
        auto=None,
        display_path=lambda name: ("copy", "no shared context"),
    )
    backend.draw(SimpleNamespace(settings=SimpleNamespace(backend="cpu")), worker)
    return imgui


def test_the_simd_line_and_its_tooltip(monkeypatch):
    info = build_info()
    imgui = draw(monkeypatch, info)
    shown = [c.args[-1] for c in imgui.text_disabled.call_args_list + imgui.text_colored.call_args_list]
    assert simd_line(info) in shown
    assert mock.call(compiler_line(info)) in imgui.set_tooltip.call_args_list
    warned = [c.args[-1] for c in imgui.text_colored.call_args_list]
    assert (simd_line(info) in warned) == (info["simd_selected"] == "scalar")


def test_a_scalar_only_build_is_shown_as_a_warning(monkeypatch):
    info = {
        **build_info(),
        "scalar_only": True,
        "simd_built": ["scalar"],
        "simd_usable": ["scalar"],
        "simd_selected": "scalar",
    }
    imgui = draw(monkeypatch, info)
    warned = [c.args[-1] for c in imgui.text_colored.call_args_list]
    assert simd_line(info) in warned and "scalar-only build" in simd_line(info)
