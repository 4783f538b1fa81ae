"""The glsl backend's storage interface, read from the shaders' own definition when imported: shaders/interface.glsl
(counter slots, record sizes, the `oit` uniform's components) and the integer constants of shaders/common.glsl
(TILE, the mode values). The driver uses these names, never the numbers, so that the kernels and the driver cannot
disagree; tests/render/test_glsl_interface.py checks them against the C++ structs.

Every name is a module attribute (`interface.TOTAL_VISIBLE`); byte sizes follow from std430's 4-byte words and
16-byte vec4.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...core.errors import BackendUnavailable
from .context import SHADER_DIR

WORD_BYTES = 4  # uint, int, float
VEC4_BYTES = 16

_CONST = re.compile(r"const\s+(?:int|uint)\s+(\w+)\s*=\s*(-?\d+)u?\s*;")


def parse(path: Path, strict: bool) -> dict[str, int]:
    """The `const int|uint NAME = VALUE;` definitions of a shader file. `strict`: every other line must be a comment
    or blank (interface.glsl holds nothing else, so nothing in it escapes this reader)."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise BackendUnavailable(f"glsl backend: shader {path} not found ({exc}); reinstall gbviewer") from None
    out: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), 1):
        code = line.split("//", 1)[0].strip()
        m = _CONST.fullmatch(code)
        if m:
            if m.group(1) in out:
                raise ValueError(f"{path}:{number}: {m.group(1)} defined twice")
            out[m.group(1)] = int(m.group(2))
        elif strict and code:
            raise ValueError(f"{path}:{number}: expected `const int|uint NAME = VALUE;` or a comment, got {code!r}")
    return out


DEFINITIONS = {**parse(SHADER_DIR / "common.glsl", strict=False), **parse(SHADER_DIR / "interface.glsl", strict=True)}
globals().update(DEFINITIONS)

TOTALS_BYTES = DEFINITIONS["TOTALS_SLOTS"] * WORD_BYTES


def totals_init() -> np.ndarray:
    """The counter buffer at the start of a frame: the depth-minimum slots at 0xFFFFFFFF, the others at 0."""
    init = np.zeros(DEFINITIONS["TOTALS_SLOTS"], np.uint32)
    init[[DEFINITIONS["TOTAL_DEPTH_MIN"], DEFINITIONS["TOTAL_CELL_DEPTH_MIN"]]] = 0xFFFFFFFF
    return init


def oit_uniform(sigma: float, weight_background: float, et_grade: float, depth_correct: bool) -> tuple:
    """The `oit` vec4 uniform (OitParams) with its components at their OIT_* positions."""
    values = {
        "OIT_SIGMA": sigma,
        "OIT_WEIGHT_BACKGROUND": weight_background,
        "OIT_ET_GRADE": et_grade,
        "OIT_DEPTH_CORRECT": float(depth_correct),
    }
    out = [0.0] * 4
    for name, value in values.items():
        out[DEFINITIONS[name]] = float(value)
    return tuple(out)


def view_filter_uniform(dilation: float, pre_dilation: float, cull_lambda: float, compensate: bool) -> tuple:
    """preprocess.comp's `view_filter` vec4 uniform (OitParams' scalar filter) at its OIT_* - 4 positions."""
    values = {
        "OIT_DILATION": dilation,
        "OIT_PRE_DILATION": pre_dilation,
        "OIT_CULL_LAMBDA": cull_lambda,
        "OIT_COMPENSATE": float(compensate),
    }
    out = [0.0] * 4
    for name, value in values.items():
        out[DEFINITIONS[name] - 4] = float(value)
    return tuple(out)


def view_rules_uniform(dc_clamp: bool, support: float, sort_radial: bool) -> tuple:
    """preprocess.comp's `view_rules` vec3 uniform (OitParams' preset rules) at its OIT_* - 8 positions."""
    values = {"OIT_DC_CLAMP": float(dc_clamp), "OIT_SUPPORT": support, "OIT_SORT_RADIAL": float(sort_radial)}
    out = [0.0] * 3
    for name, value in values.items():
        out[DEFINITIONS[name] - 8] = float(value)
    return tuple(out)


def records(vec4s: int, *columns: np.ndarray) -> np.ndarray:
    """Per-item storage records of `vec4s` vec4: the columns ((n,) or (n, k) each) side by side in float32."""
    out = np.concatenate([np.asarray(c, np.float32).reshape(len(c), -1) for c in columns], axis=1)
    if out.shape[1] != 4 * vec4s:
        raise ValueError(f"records of {out.shape[1]} floats, the shaders read {4 * vec4s}")
    return out
