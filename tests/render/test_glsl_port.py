"""The GLSL port (shaders/*.glsl) against its C++ original (native/include/gbv/*.h): the same constants, mode values,
struct fields and function names, no contractible multiply-add where the C++ multiplies through mul_rn, and the
shaders' math functions against float64."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.render.glsl import context as gl_context
from gbviewer.render.glsl import shader_source, standalone_context

pytestmark = pytest.mark.gl

REPO = Path(__file__).resolve().parents[2]
NATIVE = REPO / "native" / "include" / "gbv"
SHADERS = REPO / "shaders"


def _c_value(expr: str) -> float:
    expr = re.sub(r"(?<=[\d.])f\b", "", expr.strip())
    return float(eval(expr, {"__builtins__": {}}))  # literals and + - * / only


def constants(text: str, keyword: str) -> dict[str, tuple[str, float]]:
    """Top-level `keyword TYPE NAME = EXPR[, NAME = EXPR...];` declarations -> {name: (type, value)}."""
    out = {}
    for typ, body in re.findall(rf"^{keyword}\s+(float|int)\s+([^;]+);", text, re.M):
        for decl in body.split(","):
            name, _, expr = decl.partition("=")
            if "[" in name:
                raise AssertionError(f"array constant {name.strip()}: compare element-wise")
            out[name.strip()] = (typ, _c_value(expr))
    return out


def glsl_text(name: str) -> str:
    return re.sub(r"//[^\n]*", "", (SHADERS / name).read_text())


def cpp_text(name: str) -> str:
    return re.sub(r"//[^\n]*", "", (NATIVE / name).read_text())


@pytest.mark.parametrize(
    "headers, shader", [(["common.h"], "common.glsl"), (["preprocess.h", "sh.h", "footprint.h"], "preprocess.glsl")]
)
def test_constants_identical(headers, shader):
    """Every constant of the native headers (and enum value) has a GLSL constant of the same name, type and float32
    value, and the GLSL file has no others."""
    header = " + ".join(headers)
    text = "\n".join(cpp_text(h) for h in headers)
    c = constants(text, "constexpr")
    for body in re.findall(r"^enum\s+\w+\s*:\s*\w+\s*\{([^}]*)\}", text, re.M):
        c.update({k.strip(): ("int", float(v)) for k, v in (e.split("=") for e in body.split(",") if e.strip())})
    g = constants(glsl_text(shader), "const")
    assert c, f"no constants parsed from {header}"
    assert set(c) == set(g), f"only in {header}: {sorted(set(c) - set(g))}; only in {shader}: {sorted(set(g) - set(c))}"
    for name, (typ, val) in c.items():
        gtyp, gval = g[name]
        assert typ == gtyp, f"{name}: {typ} in {header}, {gtyp} in {shader}"
        assert np.float32(val) == np.float32(gval), f"{name}: {val!r} in {header}, {gval!r} in {shader}"


def test_mode_values_identical():
    enum = re.search(r"enum\s+Mode\s*:\s*\w+\s*\{([^}]*)\}", cpp_text("common.h")).group(1)
    c = {k.strip(): int(v) for k, v in (e.split("=") for e in enum.split(",") if e.strip())}
    g = {k: int(v) for k, (_, v) in constants(glsl_text("common.glsl"), "const").items() if k in c}
    assert c == g == {m.name: int(m) for m in gb.Mode}


# C++ functions without a GLSL function of the same name, and why.
NOT_PORTED = {
    "blend_alpha_pixel": "the shared body of C++'s one-pixel blend_scalar / blend_analytic wrappers around the lane "
    "templates; GLSL has those two functions themselves",
    "dot": "GLSL built-in",
    "stage_reach": "the stage key's reach, a uniform of stage.comp that the driver computes (glsl/stage.py "
    "Stage.build) as it keys the kept stage",
    "stage_rules": "the stage key's preset rules, a uniform of stage.comp that the driver computes (ViewFilter."
    "stage_rules) as it keys the kept stage",
    "preprocess_splat": "the one-splat composition of stage_splat and finish_splat (the C++ reference of "
    "test_fp_contract); GLSL runs the two as kernels of their own, stage.comp and preprocess.comp",
    "float_bits": "GLSL built-in floatBitsToUint",
    "splat_less": "the GLSL duplex keeps each cell's member order (cells.comp), which differs from the CPU's canonical "
    "order only by float rounding, within the tolerances above",
    "splat_key": "the field-by-field key of splat_less (same reason)",
    "in_depth_run": "CUDA's linear canonical order of equal-depth runs (splat_less's order; unused by GLSL, as above)",
    "same_depth_run": "CUDA's linear canonical order (as in_depth_run)",
    "run_pass_key": "CUDA's linear canonical order (as in_depth_run)",
    "mul_rn": "GLSL declares the values that C++ multiplies through it `precise` (test_preprocess_is_not_contracted)",
    "dmul_rn": "the double mul_rn of ray3d.h's footprint: GLSL declares those values `precise` (ray3d.glsl)",
    "to_fixed": "GLSL 4.30 core has no 64-bit integers: the wsr sums stay in float there (blend.glsl)",
    "wsr_pixel_sums": "converts the fixed-point wsr sums, which GLSL keeps in float (blend.glsl)",
    "tiles_outside": "duplex's cell_misses statistic, which the GLSL backend does not report",
}


def test_function_names_ported():
    """Every kernel function of native/include/gbv/*.h has a GLSL function of the same name in shaders/."""
    cpp = set()
    for h in NATIVE.glob("*.h"):
        cpp |= set(re.findall(r"^(?:GBV_HD|inline)\s+[\w:<>]+\s+(\w+)\s*\(", cpp_text(h.name), re.M))
    cpp.discard("operator")
    shader_src = "\n".join(glsl_text(p.name) for p in SHADERS.glob("*.glsl"))
    glsl_funcs = set(re.findall(r"^\w+\s+(\w+)\s*\(", shader_src, re.M))
    missing = sorted(cpp - glsl_funcs - set(NOT_PORTED))
    assert not missing, f"native functions without a GLSL port of the same name: {missing}"
    assert {"stage_splat", "finish_splat", "blend_gaussian", "make_camera"} <= glsl_funcs


# Functions whose C++ products go through mul_rn (common.h): no multiply-add of theirs may be contracted.
NOT_CONTRACTED = {
    "make_camera",
    "sh_basis",
    "sh_to_rgb",
    "sh_to_weight",
    "covariance_3d",
    "project_covariance",
    "splat_radius",
    "tile_rect",
    "view_point",
    "view_direction",
    "screen_position",
    "screen_footprint",
    "preprocess_stage",
    "stage_on_screen",
    "preprocess_finish",
    "preprocess_cell",
}


@pytest.mark.parametrize("shader", ["stage.comp", "preprocess.comp", "cells.comp"])
def test_preprocess_is_not_contracted(shader, tmp_path, monkeypatch):
    """The shaders compile (glslangValidator, OpenGL SPIR-V), and in the preprocess functions every multiply whose
    result feeds an add or subtract is `precise` together with that add (SPIR-V NoContraction on both), as the C++
    code routes those products through mul_rn: culling decisions and tile edges must not depend on whether the
    driver fuses multiply-adds (tests/render/test_fp_contract.py checks the C++ side bit for bit)."""
    exe = shutil.which("glslangValidator")
    if exe is None:
        skip_or_fail("glslangValidator (Debian: glslang-tools) is not installed")
    monkeypatch.setattr(gl_context, "SHADER_DIR", SHADERS)  # this checkout's shaders, not the installed copy
    src = tmp_path / shader
    src.write_text(shader_source(shader, {"GBV_PRECISE_MATH": 1}))
    p = subprocess.run(
        [exe, "-G", "--aml", "-H", str(src), "-o", str(tmp_path / "out.spv")], capture_output=True, text=True
    )
    assert p.returncode == 0, p.stdout + p.stderr
    exact = set(re.findall(r"Decorate (\d+) NoContraction", p.stdout))
    function, ops, seen, fused = None, {}, set(), []
    for line in p.stdout.splitlines():
        if m := re.match(r"\s*\d+\((\w+)\(.*\bFunction\b", line):
            function = m.group(1)
            seen.add(function)
        elif (m := re.match(r"\s*(\d+):\s+\S+\s+(FMul|FAdd|FSub|FNegate)\s+(\d+)(?:\s+(\d+))?", line)) and function:
            ident, op, args = m.group(1), m.group(2), [a for a in m.group(3, 4) if a]
            ops[ident] = op
            if op in ("FAdd", "FSub") and function in NOT_CONTRACTED:
                for a in args:
                    if ops.get(a) == "FMul" and not (ident in exact and a in exact):
                        fused.append(f"{function}: %{a} FMul -> %{ident} {op}")
    assert NOT_CONTRACTED & seen, f"none of {sorted(NOT_CONTRACTED)} found in the SPIR-V of {shader}"
    assert not fused, "multiply-adds a driver may contract:\n" + "\n".join(fused)


def _eval_glsl(fn: str, xs: np.ndarray) -> np.ndarray:
    """Evaluate the GLSL `float f(float x)` (which may call the shaders' math and blend functions) on xs."""
    ctx = standalone_context()
    src = (
        "#version 430\n#define GBV_PRECISE_MATH 1\n"
        + "".join(glsl_text(f) for f in ("common.glsl", "mathf.glsl", "blend.glsl"))
        + fn
        + """
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer X { float xs[]; };
void main() { uint i = gl_GlobalInvocationID.x; if (i < xs.length()) xs[i] = f(xs[i]); }
"""
    )
    prog = ctx.compute_shader(src)
    buf = ctx.buffer(xs.astype(np.float32).tobytes())
    buf.bind_to_storage_buffer(0)
    prog.run(-(-len(xs) // 64))
    out = np.frombuffer(buf.read(), np.float32).astype(np.float64)
    buf.release()
    prog.release()
    return out


def test_math_functions(gl):
    """expf within 2 ulp and logf within 4 ulp of float64; gaussian_moment0 (A&S 7.1.26, whose erf is good to
    1.5e-7) within 1e-6 of sqrt(pi/2) erf(x/sqrt(2)): near x = 0 the formula's 1 - poly(t) e cancels, and in
    float32 that alone costs ~7e-7 (numpy float32 evaluation of the same formula: 6.7e-7)."""
    x = np.linspace(-87.0, 88.0, 200001).astype(np.float32)
    e = _eval_glsl("float f(float x) { return expf(x); }", x)
    assert np.abs(e / np.exp(x.astype(np.float64)) - 1).max() < 1.2e-7
    y = np.concatenate([np.exp(np.linspace(-80, 80, 200001)), np.linspace(0.5, 2.0, 100001)]).astype(np.float32)
    lg = _eval_glsl("float f(float x) { return logf(x); }", y)
    ref = np.log(y.astype(np.float64))
    ulp = np.spacing(np.abs(ref).astype(np.float32)).astype(np.float64)
    assert (np.abs(lg - ref) <= 4 * ulp + 1e-12).all()
    z = np.linspace(-9.0, 9.0, 100001).astype(np.float32)
    g = _eval_glsl("float f(float x) { return gaussian_moment0(x, expf(-0.5 * x * x)); }", z)
    ref = np.array([math.sqrt(math.pi / 2) * math.erf(v / math.sqrt(2)) for v in z.astype(np.float64)])
    assert np.abs(g - ref).max() < 1e-6
