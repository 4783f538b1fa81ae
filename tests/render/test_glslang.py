"""Every GLSL program variant the glsl backend compiles passes the Khronos reference front end (glslangValidator).

Only Mesa compiles our shaders at run time here; NVIDIA's and AMD's compilers are stricter, so each variant (each
compute shader with GBV_PRECISE_MATH 0 and 1, blend.comp for every mode with and without supersampling, and
gaussian_blending's at both precisions) is checked against the reference grammar and semantics as well."""

from __future__ import annotations

import shutil
import subprocess

import pytest
from helpers import skip_or_fail

from gbviewer.render import Mode
from gbviewer.render.glsl import SHADER_DIR, shader_source
from gbviewer.render.glsl.blend import blend_defines


def variants() -> list[tuple[str, dict]]:
    out = []
    for path in sorted(SHADER_DIR.glob("*.comp")):
        for precise in (0, 1):
            if path.name == "blend.comp":
                out += [
                    (path.name, {**blend_defines(m, ss, p), "GBV_PRECISE_MATH": precise})
                    for m in Mode
                    for ss in (1, 2)
                    for p in ("exact", "fast")
                    if p == "exact" or m == Mode.GAUSSIAN_BLENDING
                ]
            else:
                out.append((path.name, {"GBV_PRECISE_MATH": precise}))
    return out


def test_every_shader_has_variants():
    names = {name for name, _ in variants()}
    assert sum(d.get("GB_FAST", 0) for _, d in variants()) == 4  # fast gaussian_blending, x1 and x2, both maths
    assert "blend.comp" in names and "preprocess.comp" in names and len(names) == len(list(SHADER_DIR.glob("*.comp")))


@pytest.mark.parametrize(
    "name,defines", variants(), ids=lambda v: v if isinstance(v, str) else "-".join(f"{k}={v}" for k, v in v.items())
)
def test_glslang_accepts(tmp_path, name, defines):
    exe = shutil.which("glslangValidator")
    if exe is None:
        skip_or_fail("glslangValidator not installed (Debian: glslang-tools)")
    src = tmp_path / name
    src.write_text(shader_source(name, defines))
    res = subprocess.run([exe, str(src)], capture_output=True, text=True)
    assert res.returncode == 0, f"{name} {defines}:\n{res.stdout}{res.stderr}"
