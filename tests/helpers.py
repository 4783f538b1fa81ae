"""Helpers shared by the tests: where the shared scenes are, skip-or-fail, small synthetic scenes and cameras."""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

import numpy as np
import pytest

import gbviewer as gb

REPO = Path(__file__).resolve().parents[1]
SHARED_SCENES = REPO.parent / "shared" / "scenes"
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")
# The suite inside scripts/check_distro.sh's root: the checks of other builds and systems (other Highways, Pythons,
# aarch64, the distro check itself) are the host suite's, which runs that one.
HOST_ONLY = pytest.mark.skipif(
    os.environ.get("GBVIEWER_IN_DISTRO_CHECK") == "1",
    reason="a check of other builds and systems: the host's suite runs it",
)


OUTPUT_W, OUTPUT_H = 96, 64  # the pane of the output-layer tests (video, figure, camera paths, keyframes)


def run_threads(work: Callable[[int], None], n: int, timeout: float = 300.0) -> None:
    """Run work(0) .. work(n - 1) in n threads at once; every thread must end within `timeout` s without raising
    (the first exception of a thread is re-raised here, the others listed)."""
    errors: list[BaseException] = []

    def run(k: int) -> None:
        try:
            work(k)
        except BaseException as exc:  # noqa: BLE001 - reported by the calling thread
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(k,), daemon=True) for k in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout)
    assert not any(t.is_alive() for t in threads), f"a thread still runs after {timeout} s"
    if errors:
        raise AssertionError(f"{len(errors)} of {n} threads raised: {errors}") from errors[0]


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


def random_scene(n: int = 100, seed: int = 0, sh_degree: int = 0, spread: float = 1.0) -> gb.Scene:
    """Random splats in front of a camera at the origin looking down +z (depths 2..6)."""
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-spread, spread, n), rng.uniform(-spread, spread, n), rng.uniform(2, 6, n)], 1)
    scales = np.exp(rng.uniform(-4.0, -1.5, (n, 3)))
    quats = rng.normal(size=(n, 4))
    opac = rng.uniform(0.05, 1.0, n)
    sh = rng.normal(0, 0.5, (n, (sh_degree + 1) ** 2, 3))
    return gb.Scene.from_arrays(means, scales, quats, opac, sh)


LOD_CAM = gb.Camera(64, 48, 20.0, 20.0, 32, 24, np.eye(3), np.zeros(3))  # the level-of-detail tests' view


def filtered_scene(seed: int, sh_dtype: str = "float32") -> gb.Scene:
    """A random scene with a 3D filter (the hierarchy merges it too), SH stored as `sh_dtype`."""
    base = random_scene(3000, seed=seed, sh_degree=2, spread=3.0)
    rng = np.random.default_rng(seed)
    return gb.Scene(
        base.means,
        base.scales,
        base.quats,
        base.opacities,
        base.sh.astype(sh_dtype),
        rng.uniform(0.0, 0.02, base.num_splats).astype(np.float32),
        source="test",
    )


def front_camera(width: int = 64, height: int = 48, f: float = 60.0) -> gb.Camera:
    return gb.Camera(width, height, f, f, width / 2, height / 2, np.eye(3), np.zeros(3))


def rotation(rng: np.random.Generator, max_angle: float) -> np.ndarray:
    """A random rotation matrix by an angle up to max_angle (radians)."""
    ax = rng.normal(size=3)
    ax /= np.linalg.norm(ax)
    ang = rng.uniform(0, max_angle)
    K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


ORTHO_DEPTH = 3.0  # random_view's orthographic camera has the perspective one's scale at this depth


def random_view(
    seed, n=160, sh_degree=3, filter3d=False, W=48, H=40, max_px_sigma=None, kinds_p=None, projection="perspective"
):
    """Random scene with every awkward kind of splat, seen by an off-centre camera (fx != fy, rotated pose).
    projection="orthographic": the same scene, seen by the same pose as an orthographic camera with the perspective
    one's scale at depth ORTHO_DEPTH (so the splats spread a little beyond the image where they are deeper).

    Kinds: normal, tiny (sub-pixel), behind (Z <= near, including negative Z), offscreen (far outside the
    frustum, exercising the Jacobian clamp), degenerate (zero scales and/or zero quaternion), huge (covering
    the image), nearplane (0.2 < Z < 0.6). `max_px_sigma` caps the projected size (well-conditioned scenes).
    """
    rng = np.random.default_rng(seed)
    fx, fy = 38.0, 43.5
    cx, cy = 0.45 * W + 1.25, 0.55 * H - 0.75
    R = rotation(rng, 0.3)
    t = rng.normal(scale=0.2, size=3)
    cam = gb.Camera(W, H, fx, fy, cx, cy, R, t)
    names = ["normal", "tiny", "behind", "offscreen", "degenerate", "huge", "nearplane"]
    p = kinds_p or [0.55, 0.15, 0.06, 0.08, 0.06, 0.04, 0.06]
    kinds = rng.choice(names, size=n, p=p)
    Zc = rng.uniform(1.0, 6.0, n)
    Xc = (rng.uniform(-0.1, 1.1, n) * W - cx) / fx * Zc
    Yc = (rng.uniform(-0.1, 1.1, n) * H - cy) / fy * Zc
    scales = np.exp(rng.uniform(np.log(0.01), np.log(0.25), (n, 3)))
    quats = rng.normal(size=(n, 4))
    op = rng.uniform(0.02, 1.0, n)
    for i, k in enumerate(kinds):
        if k == "tiny":
            scales[i] = np.exp(rng.uniform(np.log(1e-4), np.log(0.01), 3))
        elif k == "behind":
            Zc[i] = rng.uniform(-3.0, 0.2)
        elif k == "nearplane":
            Zc[i] = rng.uniform(0.2, 0.6)
        elif k == "offscreen":
            Xc[i] = rng.choice([-1, 1]) * rng.uniform(1.5, 6.0) * Zc[i]
        elif k == "degenerate":
            r = rng.integers(3)
            if r == 0:
                scales[i] = 0.0
            elif r == 1:
                scales[i, rng.integers(3)] = 0.0
            if rng.random() < 0.5:
                quats[i] = 0.0
        elif k == "huge":
            scales[i] = rng.uniform(0.5, 4.0, 3)
            op[i] = rng.uniform(0.02, 0.5)
    if max_px_sigma is not None:
        depth = np.maximum(Zc, 0.2) if projection == "perspective" else np.full(n, ORTHO_DEPTH)
        cap = max_px_sigma * depth[:, None] / max(fx, fy)
        scales = np.minimum(scales, cap)
    Pc = np.stack([Xc, Yc, Zc], -1)
    means = (Pc - t) @ R  # x_world = R^T (x_cam - t)
    sh = rng.normal(scale=0.25, size=(n, (sh_degree + 1) ** 2, 3))
    sh[:, 0] = rng.uniform(-1.5, 1.5, (n, 3))
    f3 = rng.uniform(0.0, 0.05, n) if filter3d else None
    scene = gb.Scene.from_arrays(means, scales, quats, op, sh, filter_3d=f3)
    return scene, cam.with_projection(projection, ORTHO_DEPTH)


# (seed, sh_degree, filter_3d): SH 0 and 3, filter on and off


def patch_commands(monkeypatch, name: str, value) -> None:
    """Replace `name` (e.g. `load`) in every `gbviewer.cli` subcommand module that imports it."""
    from gbviewer import cli

    for module in cli.COMMANDS:
        if hasattr(module, name):
            monkeypatch.setattr(module, name, value)
