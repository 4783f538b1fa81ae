"""The CPU blend's SIMD paths (scalar, avx2, avx512; aarch64: neon) against each other and against the float64
reference, within simd_helpers' tolerance; which path is chosen (GBVIEWER_SIMD, the CPU, an emulated older CPU).
The preprocess's paths, bit for bit: test_simd_preprocess.py.

Every path the CPU has runs; a path the CPU lacks (AVX-512 on an AVX2 machine) is skipped with that reason.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np
import pytest
from helpers import random_view, skip_or_fail
from simd_helpers import (
    ALL_PATHS,
    MODES,
    VECTOR_PATHS,
    _needle_scene,
    _small_opaque_scene,
    assert_close_to_scalar,
    render,
    simd,
)
from test_render_reference import BACKGROUND, SCENES, _check_strict

import gbviewer as gb
from gbviewer import _native


def test_paths_and_stats():
    paths = _native.simd_paths()
    assert paths[0] == "scalar" and set(paths) <= set(ALL_PATHS) and _native.simd() in paths
    if sys.platform.startswith("linux") and os.uname().machine == "x86_64" and "avx2" in _cpu_flags():
        assert "avx2" in paths, "an AVX2 CPU should get the avx2 path"
    scene, cam = random_view(1, n=40)
    for path in paths:
        assert render(path, scene, cam, "scalar").stats.simd == path
    assert gb.render(scene, cam).stats.simd == _native.simd()


@pytest.mark.parametrize(
    "mode, ran",
    [
        ("stopthepop", "scalar"),
        ("stopthepop:0", "scalar"),
        ("eval3d", "scalar"),
        ("stochastic_popfree", None),
        ("stochastic", None),
        ("gaussian_blending", None),
    ],
)
def test_stats_name_the_path_the_blend_ran(mode, ran):
    """FrameStats.simd is the path the blend ran: the per-pixel sorted modes walk one pixel at a time (no vector
    lanes) whichever path is selected; the others run the selected one."""
    scene, cam = random_view(1, n=40)
    for path in _native.simd_paths():
        assert render(path, scene, cam, mode).stats.simd == (ran or path), (mode, path)


def _cpu_flags() -> set[str]:
    try:
        text = open("/proc/cpuinfo").read()
    except OSError:
        return set()
    return set(next((ln.split(":")[1].split() for ln in text.splitlines() if ln.startswith("flags")), []))


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("supersample", [1, 2, 3])
def test_vector_matches_scalar_random(path, mode, supersample):
    for seed, sh_degree, filter3d in SCENES[:2]:
        scene, cam = random_view(seed, n=300, sh_degree=sh_degree, filter3d=filter3d, W=61, H=37)
        ref = render("scalar", scene, cam, mode, supersample, debug="window" if mode == "gaussian_blending" else "none")
        vec = render(path, scene, cam, mode, supersample, debug="window" if mode == "gaussian_blending" else "none")
        assert_close_to_scalar(vec, ref, f"{path} {mode} x{supersample} seed {seed}")
        if mode == "gaussian_blending":
            assert np.abs(vec.debug["window"] - ref.debug["window"]).mean() < 1e-4


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
def test_vector_matches_scalar_bundled(path, mode, bundled_scene):
    scene = bundled_scene
    cam = gb.orbit_camera(scene, 40, 25, width=160, height=120)
    for c in (cam, cam.at_sampling_rate(1 / 4)):
        assert_close_to_scalar(render(path, scene, c, mode), render("scalar", scene, c, mode), f"{path} {mode}")


@pytest.mark.parametrize("path", ALL_PATHS)
@pytest.mark.parametrize("mode", ["scalar", "mip", "analytic"])
def test_reference_through_each_path(path, mode):
    """The float64 reference test (strict 1e-4, ties excepted) holds on every path, not only the default one."""
    seed, sh_degree, filter3d = SCENES[1]
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d)
    with simd(path):
        for supersample in (1, 2):
            frame = gb.render(scene, cam, mode=mode, supersample=supersample, background=BACKGROUND)
            _check_strict(frame, scene, cam, mode, supersample)


@pytest.mark.parametrize("path", ALL_PATHS)
def test_reference_gaussian_blending_each_path(path):
    seed, sh_degree, filter3d = SCENES[0]
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d, max_px_sigma=1.5)
    with simd(path):
        frame = gb.render(scene, cam, mode="gaussian_blending", background=BACKGROUND)
        _check_strict(frame, scene, cam, "gaussian_blending", 1)


@pytest.mark.parametrize("path", ALL_PATHS)
@pytest.mark.parametrize("mode", ["scalar", "mip", "gaussian_blending", "gaussian_blending+fast", "wsr", "duplex"])
@pytest.mark.parametrize("make_scene", [_needle_scene, _small_opaque_scene])
def test_pixel_boxes_change_no_pixel(path, mode, make_scene):
    """Skipping lane groups outside a splat's pixel box (gaussian_blending: outside the group's window box) is exact:
    bit-identical images and evaluation counts."""
    scene, cam = make_scene(5)
    for c in (cam, cam.at_sampling_rate(1 / 2), cam.at_sampling_rate(1 / 4)):
        on = render(path, scene, c, mode, supersample=2)
        _native.testing.set_pixel_boxes(False)
        try:
            off = render(path, scene, c, mode, supersample=2)
        finally:
            _native.testing.set_pixel_boxes(True)
        np.testing.assert_array_equal(on.rgb, off.rgb)
        np.testing.assert_array_equal(on.alpha, off.alpha)
        np.testing.assert_array_equal(on.debug["evals"], off.debug["evals"])


@pytest.mark.parametrize("path", ALL_PATHS)
def test_hostile_splats_no_nan(path):
    """Degenerate splats (zero scales and quaternions), exponents that underflow (faint, far and subnormal-scaled
    splats), non-finite inputs (dropped by the scene with a warning): finite pixels on every path, within the
    vector-vs-scalar tolerance."""
    rng = np.random.default_rng(9)
    n = 300
    means = np.c_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(0.3, 50, n)]
    scales = np.exp(rng.uniform(np.log(1e-30), np.log(3.0), (n, 3)))
    scales[:20] = 0.0
    scales[20:30] = 1e-38  # subnormal squares
    quats = rng.normal(size=(n, 4))
    quats[30:40] = 0.0
    op = np.exp(rng.uniform(np.log(1.0 / 256), 0.0, n))
    op[40:50] = 1.0
    sh = rng.uniform(-1, 1, (n, 1, 3))
    means[50, 0], scales[51, 1], op[52] = np.nan, np.inf, np.nan
    with pytest.warns(UserWarning):
        scene = gb.Scene.from_arrays(means, scales, quats, op, sh)
    cam = gb.Camera(80, 60, 70.0, 70.0, 40.0, 30.0, np.eye(3), np.zeros(3))
    for mode in MODES + ("gaussian_blending+fast",):
        vec = render(path, scene, cam, mode, supersample=2)
        assert np.isfinite(vec.rgb).all() and np.isfinite(vec.alpha).all(), mode
        if path != "scalar":
            assert_close_to_scalar(vec, render("scalar", scene, cam, mode, supersample=2), f"{path} {mode}")


def _python(code: str, simd_env: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("GBVIEWER_SIMD", None)
    if simd_env is not None:
        env["GBVIEWER_SIMD"] = simd_env
    # outside the checkout, so that the installed package (with its built module) is the one imported
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120, cwd=tempfile.gettempdir()
    )


def test_env_var_forces_path():
    res = _python("import gbviewer._native as n; print(n.simd())", "scalar")
    assert res.returncode == 0 and res.stdout.strip() == "scalar", res.stderr
    res = _python("import gbviewer._native as n; print(n.simd())", None)
    assert res.stdout.strip() == _native.simd_paths()[-1]


@pytest.mark.parametrize("value", ["avx9000", "AVX2 ", "avx512"])
def test_env_var_rejects_unknown_or_unsupported(value):
    res = _python("import gbviewer._native", value)
    if value == "avx512" and "avx512" in _native.simd_paths():
        assert res.returncode == 0
        return
    assert res.returncode != 0
    assert f"GBVIEWER_SIMD={value}" in res.stderr and "available here: scalar" in res.stderr
    # the renderer says why the CPU backend is unavailable, without suggesting a reinstall
    res = _python("from gbviewer.render import CpuRenderer; print(CpuRenderer.available())", value)
    assert "GBVIEWER_SIMD" in res.stdout and "reinstall" not in res.stdout


def test_set_simd_and_exp_rate():
    with pytest.raises(ValueError, match="available here"):
        _native.testing.set_simd("sve")
    with pytest.raises(ValueError):
        _native.testing.exp_rate("sve", 1000)
    for path in _native.simd_paths():
        assert _native.testing.exp_rate(path, 100_000) > 0


_EMULATED = r"""
import sys, json, numpy as np, gbviewer as gb
from gbviewer import _native
rng = np.random.default_rng(0); n = 300
scene = gb.Scene.from_arrays(np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 4, n)], np.full((n, 3), 0.05),
                             rng.normal(size=(n, 4)), rng.uniform(0.1, 1, n), rng.uniform(-1, 1, (n, 1, 3)))
cam = gb.Camera(48, 32, 40.0, 40.0, 24.0, 16.0, np.eye(3), np.zeros(3))
out = {"paths": _native.simd_paths()}
for mode in ("scalar", "gaussian_blending", "wsr", "duplex", "analytic"):
    f = gb.render(scene, cam, mode=mode, supersample=2)
    np.save(f"{sys.argv[1]}/{mode}.npy", f.rgb)
    out[mode] = f.stats.simd
print(json.dumps(out))
"""


def emulated_env() -> dict[str, str]:
    """The emulated child's environment without what selects CPU code paths: OPENBLAS_CORETYPE=Haswell (set on some
    hosts) makes numpy's OpenBLAS run AVX2 on the emulated Nehalem and die of SIGILL, NPY_* dispatch variables and
    GBVIEWER_SIMD would force paths the emulated CPU may lack; the child must choose for the CPU it runs on."""
    return {
        k: v for k, v in os.environ.items() if not k.startswith(("OPENBLAS_", "NPY_", "GOTO", "MKL_", "GBVIEWER_SIMD"))
    }


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the x86-64 build's instruction sets")
@pytest.mark.parametrize("cpu, paths", [("Nehalem", ["scalar"]), ("Haswell", ["scalar", "avx2"])])
def test_module_runs_on_an_older_cpu(tmp_path, cpu, paths):
    """The built module on an emulated CPU (qemu-user): a Nehalem (SSE4.2, no AVX) gets the scalar path and no illegal
    instruction (nothing is built for the build machine's CPU), a Haswell gets AVX2; images match this machine's."""
    import json
    import shutil

    qemu = shutil.which("qemu-x86_64")
    if qemu is None:
        skip_or_fail("qemu-x86_64 not installed (Debian: qemu-user)")
    res = subprocess.run(
        [qemu, "-cpu", cpu, sys.executable, "-c", _EMULATED, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tempfile.gettempdir(),
        env=emulated_env(),
    )
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["paths"] == paths
    rng = np.random.default_rng(0)
    n = 300
    scene = gb.Scene.from_arrays(
        np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(2, 4, n)],
        np.full((n, 3), 0.05),
        rng.normal(size=(n, 4)),
        rng.uniform(0.1, 1, n),
        rng.uniform(-1, 1, (n, 1, 3)),
    )
    cam = gb.Camera(48, 32, 40.0, 40.0, 24.0, 16.0, np.eye(3), np.zeros(3))
    for mode in ("scalar", "gaussian_blending", "wsr", "duplex", "analytic"):
        assert out[mode] == paths[-1]
        here = render(paths[-1], scene, cam, mode, supersample=2).rgb
        assert np.abs(np.load(tmp_path / f"{mode}.npy") - here).max() < 1e-5, f"{cpu} {mode}"
