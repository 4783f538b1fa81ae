"""Test setup: the package under test (installed or this source tree) and the session fixtures; plain helpers are
in helpers.py."""

from __future__ import annotations

import sys
from pathlib import Path

# `python -m pytest` run from the repository root puts the source tree first on sys.path, and its gbviewer/
# has no compiled _native (the build installs that into site-packages). Prefer the installed package then.
_SRC = Path(__file__).resolve().parents[1]
if not any((_SRC / "gbviewer").glob("_native*")):
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _SRC]

sys.path.insert(0, str(_SRC / "tools"))  # developer tools the tests share with bench/: encoders, fuzz_loaders

import pytest  # noqa: E402
from dataset_builders import shots, write_colmap  # noqa: E402
from helpers import OUTPUT_H, OUTPUT_W  # noqa: E402

import gbviewer as gb  # noqa: E402


@pytest.fixture(scope="session")
def bundled_scene() -> gb.Scene:
    return gb.load(gb.DEFAULT_SCENE)


@pytest.fixture(scope="session")
def output_view(bundled_scene) -> gb.Camera:
    """The bundled scene from a 30, 20 degree orbit at OUTPUT_W x OUTPUT_H (the output-layer tests' pane)."""
    return gb.orbit_camera(bundled_scene, 30, 20, width=OUTPUT_W, height=OUTPUT_H)


@pytest.fixture(scope="session")
def capture(bundled_scene, tmp_path_factory):
    """A COLMAP capture of the bundled scene (`dataset_builders.shots`), for `gbviewer eval`."""
    pytest.importorskip("pycolmap")
    return write_colmap(tmp_path_factory.mktemp("colmap"), shots(bundled_scene))
