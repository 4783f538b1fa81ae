"""The exact path stays bit for bit what it was: every shared scene in every mode, on every SIMD path this CPU has,
hashes to the digests recorded (tests/render/data/exact_digests.json) by the module before the fast Gaussian Blending
path existed. Digests depend on the compiler and libm, so they are keyed by the toolchain that recorded them; on
another toolchain the test skips saying so (record afresh with
`PYTHONPATH=tests python tests/render/test_exact_digests.py` on the module before a change)."""

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

DIGESTS = Path(__file__).parent / "data" / "exact_digests.json"
SCENES = sorted(p.name for p in SHARED_SCENES.glob("*") if p.suffix != ".md")
SPECS = [m.label for m in Mode]
PATHS = ("scalar", "avx2", "avx512")


def toolchain() -> str:
    """What the digests depend on besides the source: the module's compiler and the C library."""
    info = _native.build_info() if hasattr(_native, "build_info") else {}
    libc = platform.libc_ver()[1]
    return f"{info.get('compiler', '?')} hwy {info.get('highway', '?')} libc {libc} {platform.machine()}"


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
            f = r.render(cam, RenderSettings.parse(spec))
            h = hashlib.sha256()
            for a in (f.rgb, f.alpha, f.debug["evals"]):
                h.update(np.ascontiguousarray(a).tobytes())
            out[spec] = h.hexdigest()
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


if __name__ == "__main__":
    table = {"toolchain": toolchain()}
    for p in PATHS:
        if p in _native.simd_paths():
            table[p] = {n: digests(p, n) for n in SCENES}
    DIGESTS.write_text(json.dumps(table, indent=1) + "\n")
