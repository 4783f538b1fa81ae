"""The CPU preprocess's SIMD paths (gbv/preprocess.h, 8 or 16 splats per call; aarch64: neon) against the scalar
path, bit for bit: every Splat2D field, tile rectangle and culling decision, in every mode and preset, and for a
level-of-detail cut's rows. A path the CPU lacks is skipped with that reason (simd_helpers.simd)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_view
from simd_helpers import MODES, SPLAT2D, VECTOR_PATHS, _needle_scene, preprocessed, render
from test_render_reference import SCENES

import gbviewer as gb
from gbviewer import _native, lod
from gbviewer.model.cells import build_cells


def _cut_scene(seed):
    """Splats at the preprocess's cuts: opacities at and next to 1/255 and 1/256 (after the mip compensation too),
    depths at and next to the near plane, view weights near 0 (a sum of terms), 3D filters, subnormal and zero
    scales; n = 1003 leaves a partial vector at the end."""
    rng = np.random.default_rng(seed)
    n = 1003
    z = rng.uniform(0.15, 8.0, n)
    z[:40] = np.nextafter(np.float32(0.2), np.float32([0.0, 1.0] * 20))
    means = np.c_[rng.uniform(-1.3, 1.3, n) * z, rng.uniform(-1.3, 1.3, n) * z, z]
    scales = np.exp(rng.uniform(np.log(1e-4), np.log(0.5), (n, 3)))
    scales[40:60] = 0.0
    scales[60:80, :2] = 1e-38
    op = rng.uniform(0.003, 1.0, n).astype(np.float32)
    for i, o in enumerate((1 / 255, 1 / 256)):
        base = np.float32(o)
        op[100 + 30 * i : 130 + 30 * i] = np.nextafter(base, np.float32([0.0, 1.0, 1.0] * 10))
        op[160 + 10 * i : 170 + 10 * i] = base
    quats = rng.normal(size=(n, 4))
    quats[80:90] = 0.0
    sh = rng.uniform(-1, 1, (n, 16, 3))
    vw = rng.normal(0.0, 0.4, (n, 16))
    vw[:, 0] = rng.uniform(-0.5, 4.0, n)
    vw[200:300, 1:] = 0.0
    vw[200:300, 0] = np.float32(rng.choice([0.0, 1e-30, -1e-30, 1e-3], 100))
    f3d = np.where(rng.random(n) < 0.5, rng.uniform(0.0, 0.05, n), 0.0)
    scene = gb.Scene.from_arrays(
        means, scales, quats, op, sh, f3d, view_weight_sh=vw, wsr_sigma=5.0, weight_background=0.3
    )
    R = np.array([[0.98, -0.17, 0.1], [0.17, 0.985, 0.0], [-0.1, 0.02, 0.995]])
    R = np.linalg.qr(R)[0] * np.sign(np.diag(np.linalg.qr(R)[1]))
    return scene, gb.Camera(97, 61, 52.3, 47.9, 50.1, 29.7, R, np.array([0.03, -0.02, 0.1]))


def _gapped_scene():
    """16 splats, all on screen but splat 14 (behind the camera), SH degree 3: the stage's second colour group holds
    splats 8-13 and 15 with a spare lane, whose first and last rows are 7 apart though they are not 8 consecutive rows
    (a vector path that took them for a run would read splat 14's mean for splat 15's view direction)."""
    rng = np.random.default_rng(3)
    n = 16
    means = np.c_[rng.uniform(-1, 1, n), rng.uniform(-0.6, 0.6, n), rng.uniform(2.5, 4, n)]
    means[14, 2] = -1.0
    quats = rng.normal(size=(n, 4))
    scene = gb.Scene(
        means,
        np.full((n, 3), 0.05),
        quats / np.linalg.norm(quats, axis=1, keepdims=True),
        np.full(n, 0.8),
        rng.uniform(-0.5, 0.5, (n, 16, 3)),
        source="gapped",
    )
    return scene, gb.Camera(64, 48, 40.0, 40.0, 32, 24, np.eye(3), np.zeros(3))


def _preprocess_cases():
    yield "gapped", _gapped_scene()
    for seed, sh_degree, filter3d in SCENES[:3]:
        yield f"random{seed}", random_view(seed, n=777, sh_degree=sh_degree, filter3d=filter3d, W=61, H=37)
    yield "needles", _needle_scene(5)
    yield "cuts", _cut_scene(7)
    scene, cam = _cut_scene(7)
    yield "cuts orthographic", (scene, cam.with_projection("orthographic", 2.0))


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("mode", MODES)
def test_preprocess_bitwise(path, mode):
    """The vector preprocess gives every splat's Splat2D (every field, bit for bit), tile rectangle and culling decision
    exactly as the scalar one, in every mode, SH degree, with 3D filters, view weights, depth correction and cells,
    for perspective and orthographic cameras."""
    for name, (scene, cam) in _preprocess_cases():
        variants = [{}]
        if mode in ("wsr", "duplex"):
            variants.append({"depth_correct": True})
        if mode == "duplex":
            scene = gb.Scene.from_arrays(
                scene.means,
                scene.scales,
                scene.quats,
                scene.opacities,
                scene.sh,
                scene.filter_3d,
                view_weight_sh=scene.oit and scene.oit.view_weight_sh,
                cells=build_cells(scene, 6),
            )
        for kw in variants + [{"sh_degree": 1}, {"sh_degree": 2}]:
            ref, ref_frame = preprocessed("scalar", scene, cam, mode, **kw)
            vec, vec_frame = preprocessed(path, scene, cam, mode, **kw)
            what = f"{path} {mode} {name} {kw}"
            assert ref["valid"].sum() > 0 and (ref["valid"] == 0).sum() > 0, what
            as_bytes = lambda r: r.view(np.uint8).reshape(len(r), -1)  # noqa: E731
            bad = np.flatnonzero((as_bytes(ref) != as_bytes(vec)).any(axis=1))
            if len(bad):
                fields = [f for f in SPLAT2D.names if (ref["splat"][f][bad] != vec["splat"][f][bad]).any()]
                decided = (ref["valid"][bad] != vec["valid"][bad]).sum()
                rects = (ref["rect"][bad] != vec["rect"][bad]).any(axis=1).sum()
                pytest.fail(
                    f"{what}: {len(bad)} splats differ (first {bad[:5]}): {decided} decisions, {rects} "
                    f"rectangles, fields {fields}"
                )
            for stat in ("visible", "sort_length", "pairs"):
                assert getattr(vec_frame.stats, stat) == getattr(ref_frame.stats, stat), what


@pytest.mark.parametrize("path", VECTOR_PATHS)
@pytest.mark.parametrize("preset", ["spark", "antimatter15"])
def test_preset_rules_preprocess_bitwise(path, preset):
    """The presets' rules (base-colour clamp, support cut, radial depth) keep the vector preprocess the scalar one's,
    bit for bit."""
    for name, (scene, cam) in _preprocess_cases():
        ref, _ = preprocessed("scalar", scene, cam, f"preset:{preset}")
        vec, _ = preprocessed(path, scene, cam, f"preset:{preset}")
        assert ref["valid"].sum() > 0 and ref.tobytes() == vec.tobytes(), f"{path} {preset} {name}"


@pytest.mark.parametrize("path", VECTOR_PATHS)
def test_lod_preprocess_bitwise(path):
    """A level-of-detail frame's preprocess (the stage reads a cut's scattered rows: scene leaves, then hierarchy
    nodes, opacities times the cut's weights) is the scalar path's, bit for bit, with a 3D filter and every SH
    degree."""
    seed = SCENES[2][0]
    scene, cam = random_view(seed, n=3000, sh_degree=3, filter3d=True, W=61, H=37)
    tree = lod.build(scene)  # the hierarchy the renderer draws (the same build; its cache is not needed here)
    for tau in (32.0, 64.0):  # these splats are large against the 61 x 37 image: cuts of 150-200 nodes
        for degree in (3, 2, 0):
            out = []
            for p in ("scalar", path):
                _native.testing.set_capture_preprocess(True)
                try:
                    frame = render(p, scene, cam, "gaussian_blending", lod=tau, sh_degree=degree)
                    out.append(_native.testing.captured_preprocess())
                finally:
                    _native.testing.set_capture_preprocess(False)
            what = f"{path} lod {tau} sh {degree}"
            assert len(lod.cut(tree, cam, tau).nodes) > 100 and frame.stats.lod_splats > 100, what
            assert out[0] == out[1], what
