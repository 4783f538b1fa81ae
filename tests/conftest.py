"""Shared fixtures: paths to the shared scenes and small synthetic scenes."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import NoReturn

# `python -m pytest` run from the repository root puts the source tree first on sys.path, and its gbviewer/
# has no compiled _native (the build installs that into site-packages). Prefer the installed package then.
_SRC = Path(__file__).resolve().parents[1]
if not any((_SRC / "gbviewer").glob("_native*")):
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _SRC]

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import gbviewer as gb  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED_SCENES = REPO.parent / "shared" / "scenes"
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def skip_or_fail(reason: str) -> NoReturn:
    """Skip, saying why, where a prerequisite is missing; in CI (CI=true), which installs everything and has
    shared/ beside the clone, a missing prerequisite is a failure rather than a silently skipped path."""
    if IN_CI:
        pytest.fail(f"CI=true but {reason}")
    pytest.skip(reason)


def shared_scene(name: str) -> Path:
    """Path of a scene in ../shared/scenes (see skip_or_fail where that folder is absent)."""
    path = SHARED_SCENES / name
    if not path.exists():
        skip_or_fail(f"{path} not present (shared/ is not beside this checkout)")
    return path


@pytest.fixture(scope="session")
def bundled_scene() -> gb.Scene:
    return gb.load(gb.DEFAULT_SCENE)


def random_scene(n: int = 100, seed: int = 0, sh_degree: int = 0, spread: float = 1.0) -> gb.Scene:
    """Random splats in front of a camera at the origin looking down +z (depths 2..6)."""
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-spread, spread, n), rng.uniform(-spread, spread, n), rng.uniform(2, 6, n)], 1)
    scales = np.exp(rng.uniform(-4.0, -1.5, (n, 3)))
    quats = rng.normal(size=(n, 4))
    opac = rng.uniform(0.05, 1.0, n)
    sh = rng.normal(0, 0.5, (n, (sh_degree + 1) ** 2, 3))
    return gb.Scene.from_arrays(means, scales, quats, opac, sh)


def front_camera(width: int = 64, height: int = 48, f: float = 60.0) -> gb.Camera:
    return gb.Camera(width, height, f, f, width / 2, height / 2, np.eye(3), np.zeros(3))


OUTPUT_W, OUTPUT_H = 96, 64  # the pane of the output-layer tests (video, figure, camera paths, keyframes)


@pytest.fixture(scope="session")
def output_view(bundled_scene) -> gb.Camera:
    """The bundled scene from a 30, 20 degree orbit at OUTPUT_W x OUTPUT_H."""
    return gb.orbit_camera(bundled_scene, 30, 20, width=OUTPUT_W, height=OUTPUT_H)
