"""How the native modules were built (`gbviewer.build_info()`): the CPU module's SIMD paths (built, usable on this
CPU, selected now), its scalar-only switch, OpenMP, compiler and flags, and whether the CUDA module was built."""

from __future__ import annotations

import importlib.util
from typing import Any


def build_info() -> dict[str, Any]:
    """The CPU module's own report (gbviewer._native.build_info) plus whether the CUDA module is installed; without a
    usable CPU module, {"cpu_module": False, "reason": why}."""
    try:
        from .. import _native
    except ImportError as e:
        return {"cpu_module": False, "reason": f"gbviewer._native does not import ({e}): rebuild with pip install ."}
    if not hasattr(_native, "build_info"):
        return {"cpu_module": False, "reason": f"{_native.__file__} predates build_info(): rebuild with pip install ."}
    info: dict[str, Any] = {"cpu_module": True, **_native.build_info()}
    info["cuda_module_installed"] = importlib.util.find_spec("gbviewer._native_cuda") is not None
    return info


def simd_line(info: dict[str, Any]) -> str:
    """One line: the SIMD path in use and what was built, loud when scalar-only by choice or for lack of a path."""
    if not info["cpu_module"]:
        return f"CPU module unavailable: {info['reason']}"
    line = (
        f"SIMD {info['simd_selected']} (built: {', '.join(info['simd_built'])}; this CPU: "
        f"{', '.join(info['simd_usable'])})"
    )
    if info["scalar_only"]:
        line += " - scalar-only build (GBVIEWER_SCALAR_ONLY): 3-5x slower blend"
    return line


def compiler_line(info: dict[str, Any]) -> str:
    """One line: compiler, build type, flags, OpenMP and the CUDA module."""
    if not info["cpu_module"]:
        return ""
    omp = f"OpenMP {info['openmp']}" if info["openmp"] else "no OpenMP"
    cuda = "CUDA module built" if info["cuda_module_built"] else "no CUDA module"
    isa = f"; {info['isa_flags']}" if info["isa_flags"] else ""
    if info.get("highway"):
        isa += f"; Highway {info['highway']}"
    return f"{info['compiler']} {info['build_type']} [{info['flags']}{isa}], {omp}, {cuda}"


__all__ = ["build_info", "compiler_line", "simd_line"]
