"""The exact path stays bit for bit what it was: every shared scene in every mode, on every SIMD path this CPU has,
hashes to the digests recorded (tests/render/data/exact_digests.json) by the module before the fast Gaussian Blending
path existed. Digests depend on the compiler and libm, so they are keyed by the toolchain that recorded them; on
another toolchain the test skips saying so (record afresh with
`PYTHONPATH=tests python tests/render/test_exact_digests.py` on the module before a change). The glsl backend's exact
gaussian_blending (the kernel that shares its shader with the fast one) likewise, keyed by the OpenGL driver."""

from __future__ import annotations

import hashlib
import json
import platform
from pathlib import Path

import numpy as np
import pytest
from helpers import SHARED_SCENES, shared_scene, skip_or_fail

import gbviewer as gb
from gbviewer import _native
from gbviewer.render import Mode, RenderSettings, create_renderer
from gbviewer.render.glsl import standalone_context

DIGESTS = Path(__file__).parent / "data" / "exact_digests.json"
SCENES = sorted(p.name for p in SHARED_SCENES.glob("*") if p.suffix != ".md")
SPECS = [m.label for m in Mode]
PATHS = ("scalar", "avx2", "avx512")
GLSL_SPECS = ("gaussian_blending", "gaussian_blending:2")


def toolchain() -> str:
    """What the digests depend on besides the source: the module's compiler and the C library."""
    info = _native.build_info() if hasattr(_native, "build_info") else {}
    libc = platform.libc_ver()[1]
    return f"{info.get('compiler', '?')} hwy {info.get('highway', '?')} libc {libc} {platform.machine()}"


def frame_digest(f: gb.Frame) -> str:
    h = hashlib.sha256()
    for a in (f.rgb, f.alpha, f.debug["evals"]):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def gl_driver() -> str:
    """What the glsl digests depend on besides the shaders: the OpenGL renderer and version (Mesa's, here)."""
    info = standalone_context().info
    return f"{info['GL_RENDERER']} {info['GL_VERSION']}"


def glsl_digests(name: str) -> dict[str, str]:
    """sha256 of rgb, alpha and evals of one scene in GLSL_SPECS on the glsl backend (96x72, exact)."""
    scene = gb.load(shared_scene(name))
    cam = gb.orbit_camera(scene, 30, 20, width=96, height=72)
    r = create_renderer("glsl")
    r.upload(scene)
    return {spec: frame_digest(r.render(cam, RenderSettings.parse(spec))) for spec in GLSL_SPECS}


def digests(path: str, name: str) -> dict[str, str]:
    """sha256 of rgb, alpha and evals of one scene in every mode on SIMD path `path` (160x120, exact)."""
    scene = gb.load(shared_scene(name))
    cam = gb.orbit_camera(scene, 30, 20, width=160, height=120)
    before = _native.simd()
    _native.testing.set_simd(path)
    try:
        r = create_renderer("cpu")
        r.upload(scene)
        out = {}
        for spec in SPECS:
            out[spec] = frame_digest(r.render(cam, RenderSettings.parse(spec)))
        return out
    finally:
        _native.testing.set_simd(before)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", SCENES)
def test_exact_renders_are_unchanged(path, name):
    recorded = json.loads(DIGESTS.read_text())
    if recorded["toolchain"] != toolchain():
        skip_or_fail(f"digests recorded with {recorded['toolchain']!r}, this module is {toolchain()!r}")
    if path not in _native.simd_paths():
        pytest.skip(f"this CPU/build has no {path} path")
    assert digests(path, name) == recorded[path][name]


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_glsl_exact_gaussian_blending_is_unchanged(gl, name):
    recorded = json.loads(DIGESTS.read_text())["glsl"]
    if recorded["driver"] != gl_driver():
        skip_or_fail(f"glsl digests recorded with {recorded['driver']!r}, this driver is {gl_driver()!r}")
    assert glsl_digests(name) == recorded[name]


if __name__ == "__main__":
    table = {"toolchain": toolchain()}
    for p in PATHS:
        if p in _native.simd_paths():
            table[p] = {n: digests(p, n) for n in SCENES}
    table["glsl"] = {"driver": gl_driver(), **{n: glsl_digests(n) for n in SCENES}}
    DIGESTS.write_text(json.dumps(table, indent=1) + "\n")
