"""Shared by the glsl backend's tests (test_glsl*.py): the `gl` fixture, the GLSL-vs-CPU comparison and its
tolerances, and the awkward random scene.

Tolerances (GLSL vs CPU, same scene, camera and settings): mean absolute rgb difference < 1e-3 and max < 1/255 on
every pixel except threshold pixels, of which at most THRESHOLD_FRACTION (0.2%) per image are allowed.

Why there are threshold pixels at all: both backends run the same float32 formulas, but not bit-identically
(the C++ build contracts a*b+c into FMAs where g++ chooses, llvmpipe where LLVM chooses; the shaders' expf/logf
are ~1-2 ulp polynomials, glibc's are correctly rounded to ~0.5 ulp). The results differ by ~1e-7 relative, so
a decision `alpha < 1/255` (1/256), `T(1 - alpha) < 1e-4` or a ceil() of the splat radius goes the other way only
when the value lies within ~1e-6 of the cut. One flipped alpha cut costs at most ~(1/255) x colour in scalar
modes; in Gaussian Blending it also changes the window, so later splats integrate over a slightly different
window and the pixel can move by more (the float32 window cancellation described in test_render_reference.py).
Measured on llvmpipe (Mesa 22.3), 56 comparisons below: 0 pixels over 1/255 in every mode; mean differences
<= 1e-7 (scalar, mip), 6e-7 (analytic), 2e-6 (gaussian_blending); max differences 5e-5 (scalar, mip at x1),
1e-3 (analytic), 6e-4 (scalar 2x2), 2e-3 (gaussian_blending; its per-pixel evaluation counts differ on up to 37
pixels of an image, i.e. the 1e-4 stop fell one splat apart). The 0.2% bound leaves room for other drivers
(NVIDIA/AMD/Intel evaluate exp/log and contract FMAs differently) without hiding a real formula difference, which
moves most pixels of an image by more than 1/255.

`visible` and `pairs` (tile-list entries) must match exactly up to the same kind of flip (bounded by 1e-4 of the
splats)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_scene, skip_or_fail

import gbviewer as gb
from gbviewer.render import RenderSettings
from gbviewer.render.glsl import GlslRenderer

MEAN_TOL = 1e-3
MAX_TOL = 1.0 / 255.0
THRESHOLD_FRACTION = 0.002
COUNT_SLACK = 1e-4  # visible / pairs: allowed relative difference (threshold flips, see above)

MODES = ["scalar", "mip", "analytic", "gaussian_blending", "scalar:2", "gaussian_blending:2", "wsr", "duplex"]


@pytest.fixture(scope="module")
def gl():
    """Skip (printing why) only where no OpenGL 4.3 context can be created; in CI a failure (skip_or_fail)."""
    ok, why = GlslRenderer.available()
    if not ok:
        print(f"\nglsl backend unavailable: {why}")
        skip_or_fail(why)


def compare(
    scene: gb.Scene,
    cam: gb.Camera,
    spec: str,
    renderer: GlslRenderer | None = None,
    background=(0.0, 0.0, 0.0),
    **options,
) -> dict:
    """Render with both backends; assert the tolerances of the module docstring; return the measurements."""
    settings = RenderSettings.parse(spec, background=background, **options)
    ref = gb.get_renderer(scene, "cpu").render(cam, settings)
    out = (renderer or gb.get_renderer(scene, "glsl")).render(cam, settings)
    assert out.rgb.shape == ref.rgb.shape and out.alpha.shape == ref.alpha.shape
    assert np.isfinite(out.rgb).all() and np.isfinite(out.alpha).all(), "NaN/inf in the GLSL output"
    diff = np.maximum(np.abs(out.rgb - ref.rgb).max(-1), np.abs(out.alpha - ref.alpha))
    m = {
        "mean": float(np.abs(out.rgb - ref.rgb).mean()),
        "max": float(diff.max()),
        "over": int((diff > MAX_TOL).sum()),
        "evals_differ": int((out.debug["evals"] != ref.debug["evals"]).sum()),
    }
    where = f"{scene.source} {cam.width}x{cam.height} {spec}: {m}"
    print(where)
    assert m["mean"] < MEAN_TOL, where
    assert m["over"] <= THRESHOLD_FRACTION * diff.size, where
    for key in ("visible", "pairs"):  # sort_length: the cpu sorts one key per splat
        a, b = getattr(out.stats, key), getattr(ref.stats, key)
        assert abs(a - b) <= COUNT_SLACK * max(b, 1), f"{where}: {key} {a} vs cpu {b}"
    return m


def awkward_scene(seed: int, n: int = 1500, filter3d: bool = False) -> gb.Scene:
    """conftest.random_scene plus the cases that stress binning and culling: splats behind the near plane, far
    off-screen, huge (covering many tiles), degenerate (zero scale), and exact depth ties (copies of splats with
    other colours, which only the (depth, index) order of the tile lists resolves like the CPU)."""
    base = random_scene(n, seed=seed, sh_degree=3, spread=1.5)
    rng = np.random.default_rng(seed + 100)
    means, scales, quats = base.means.copy(), base.scales.copy(), base.quats.copy()
    opac, sh = base.opacities.copy(), base.sh.copy()
    k = n // 10
    means[:k, 2] = rng.uniform(-1.0, 0.25, k)  # behind / at the near plane
    means[k : 2 * k, :2] = rng.uniform(-40, 40, (k, 2))  # far off-screen (Jacobian clamp)
    scales[2 * k : 2 * k + 10] = rng.uniform(0.3, 1.0, (10, 3))  # huge
    scales[2 * k + 10 : 2 * k + 20, 0] = 0.0  # flat
    dup = rng.choice(np.arange(3 * k, n), 50, replace=False)
    means = np.concatenate([means, means[dup]])
    scales, quats = np.concatenate([scales, scales[dup]]), np.concatenate([quats, quats[dup]])
    opac = np.concatenate([opac, np.full(50, 0.9, np.float32)])
    sh = np.concatenate([sh, rng.normal(0, 1.0, sh[dup].shape).astype(np.float32)])
    f3d = rng.uniform(0.0, 0.02, len(means)) if filter3d else None
    return gb.Scene.from_arrays(means, scales, quats, opac, sh, f3d, source=f"awkward({seed}, filter3d={filter3d})")
