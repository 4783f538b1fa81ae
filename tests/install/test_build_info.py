"""Never silently slow: gb.build_info() and `gbviewer info` report the CPU module's build (the builds
of other configurations are in test_build_variants.py and test_aarch64.py)."""

from __future__ import annotations

import json
import os
import platform
import re
from pathlib import Path

import gbviewer as gb
from gbviewer import _native
from gbviewer.cli import main
from gbviewer.render import simd_line

X86 = platform.machine() in ("x86_64", "AMD64")
ARM64 = platform.machine() in ("aarch64", "arm64")


def cpu_flags() -> set[str]:
    """This CPU's feature flags (/proc/cpuinfo), to know which paths the module must offer here."""
    text = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    line = next((ln for ln in text.splitlines() if ln.startswith("flags")), "")
    return set(line.split(":", 1)[-1].split())


def test_build_info_matches_the_module():
    info = gb.build_info()
    assert info["cpu_module"] is True
    assert info["simd_usable"] == _native.simd_paths() and info["simd_selected"] == _native.simd()
    assert set(info["simd_usable"]) <= set(info["simd_built"]) and info["simd_built"][0] == "scalar"
    assert info["openmp"] and info["compiler"] and "-ffp-contract=off" in info["flags"]
    if X86 and not info["scalar_only"]:  # a vector build (the default; the switch is off here)
        assert info["simd_built"] == ["scalar", "avx2", "avx512"] and "-mavx2" in info["isa_flags"]
        assert re.fullmatch(r"1\.\d+\.\d+", info["highway"]), info["highway"]  # the headers' version
        if {"avx2", "fma", "bmi2", "f16c"} <= cpu_flags():
            assert "avx2" in info["simd_usable"]
            if not os.environ.get("GBVIEWER_SIMD"):
                assert info["simd_selected"] == info["simd_usable"][-1] != "scalar"
    if ARM64 and not info["scalar_only"]:
        assert info["simd_built"] == info["simd_usable"] == ["scalar", "neon"]


def test_gbviewer_info_prints_the_build(capsys):
    assert main(["info"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[0] == simd_line(gb.build_info())
    assert lines[0].startswith(f"SIMD {_native.simd()} (built: scalar") and gb.build_info()["compiler"] in lines[1]
    assert main(["info", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["simd_usable"] == _native.simd_paths()
    assert main(["info", str(gb.DEFAULT_SCENE), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["build"]["simd_selected"] == _native.simd()
