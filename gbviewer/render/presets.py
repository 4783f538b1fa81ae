"""Viewer presets: how other viewers render a splat scene, as a mode plus parameters (`--mode preset:NAME`), and the
mode a scene was trained with (`trained_spec`). Each preset names the viewer code it reproduces and what of that
viewer it does not model (their quantisation, alpha cut-offs and tile-free rasterisation stay gbviewer's scalar
mode's). The rules beyond the 2D filter (ViewFilter's dc_clamp, support, sort_radial):

- base colour clamped to [0, 1] before the SH bands: sparkjsdev/spark src/utils.ts (setPackedSplat: each channel
  (v - rgbMin) / (rgbMax - rgbMin) to 8 bits, rgbMin 0, rgbMax 1 without a splat encoding) and
  src/shaders/splatVertex.glsl (the higher bands added to the unpacked colour); antimatter15/splat main.js
  (processPlyBuffer: 0.5 + SH_C0 f_dc into a Uint8ClampedArray). PlayCanvas keeps it unclamped (playcanvas/engine
  src/scene/gsplat/gsplat-resource.js updateColorData: half floats);
- support sqrt(8) sigma: sparkjsdev/spark src/SparkRenderer.ts (maxStdDev ?? Math.sqrt(8)), splatFragment.glsl
  (discard when z2 > adjustedStdDev^2); playcanvas/engine gsplatCorner.js (l = 2 sqrt(2 lambda)) and frag/gsplat.js
  (discard when A = |uv|^2 > 1); antimatter15/splat main.js (quad 2 sqrt(2 lambda), discard when A < -4);
- radial sort: sparkjsdev/spark src/SparkRenderer.ts (sortRadial ?? true); playcanvas/engine
  src/scene/gsplat-unified/gsplat-params.js (radialSorting = false) and antimatter15/splat main.js (view-projection z)
  sort by depth.

| preset | source (repository: file) | what it sets |
| inria | graphdeco-inria/diff-gaussian-rasterization: cuda_rasterizer/forward.cu (computeCov2D), the rasterizer SIBR's
  gaussian viewer runs | +0.3 px^2, SH 3: the scalar mode itself |
| gsplat-antialiased | nerfstudio-project/gsplat: gsplat/cuda/include/utils.cuh (add_blur), gsplat/rendering.py
  (rasterization: eps2d = 0.3, rasterize_mode="antialiased" multiplies opacities by the compensation) |
  +eps2d, opacity * sqrt(max(0, det_orig / det_blur)) |
| supersplat | playcanvas/engine: src/scene/shader-lib/glsl/chunks/gsplat/vert/gsplatCorner.js (+0.3; early-out when
  l1, l2 = 2 min(sqrt(2 lambda), vmin) are both < 2 px, i.e. lambda_max < 0.5 px^2); playcanvas/supersplat:
  src/ui/view-panel.ts (SH bands slider, default 3) | +0.3, cull lambda_max < 0.5, SH 3, support sqrt(8) |
| spark | sparkjsdev/spark: src/SparkRenderer.ts (preBlurAmount ?? 0.0, blurAmount ?? 0.3), src/shaders/splatVertex.glsl
  (a += preBlurAmount; detOrig; a += blurAmount; alpha *= sqrt(max(0, detOrig / det))) | as gsplat-antialiased, base
  colour clamped, support sqrt(8), radial sort |
| supersplat-stochastic | playcanvas/engine: src/scene/shader-lib/glsl/chunks/gsplat/frag/gsplat.js (opacityDither with
  the splat id * 0.013 as offset), src/scene/shader-lib/glsl/chunks/standard/frag/opacity-dither.js (discard when
  alpha < the dither's noise) | the stochastic mode with supersplat's filter and rules |
| spark-stochastic | sparkjsdev/spark: src/shaders/splatFragment.glsl (#ifdef STOCHASTIC: uniform from a hash of time,
  pixel and splat index; kept when below alpha, written opaque; SparkViewpoint.stochastic) | the stochastic mode with
  spark's filter and rules |
| antimatter15 | antimatter15/splat: main.js (the vertex shader adds nothing to cov2d; .splat rows hold an 8-bit colour,
  no SH) | +0, SH 0, base colour clamped, support sqrt(8) |
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..io.trained_as import ANTIALIASED, MIP_3D, THREEDGS
from .view_filter import ViewFilter

if TYPE_CHECKING:
    from .types import RenderSettings


@dataclass(frozen=True)
class Preset:
    """A viewer's rendering convention: mode, SH bands, filter, where it comes from and what is not modelled."""

    name: str
    mode: str  # a Mode label (this module sits below types, which parses presets with it)
    sh_degree: int
    view_filter: ViewFilter
    source: str
    not_modelled: str

    def describe(self) -> str:
        return f"{self.mode}, {self.view_filter.describe()}, SH {self.sh_degree}"


QUAD_SIGMAS = math.sqrt(8.0)  # the quad's half side in sigmas in Spark, PlayCanvas and antimatter15 (module docstring)
# each viewer's filter and rules, shared by its scalar and stochastic presets
SUPERSPLAT_FILTER = ViewFilter(0.3, cull_lambda=0.5, support=QUAD_SIGMAS)
SPARK_FILTER = ViewFilter(0.3, pre_dilation=0.0, compensate=True, dc_clamp=True, support=QUAD_SIGMAS, sort_radial=True)
# The modes a preset's 2D filter applies to: those whose alpha is 3DGS's at the pixel centre.
FILTERED_MODES = ("scalar", "stochastic", "stochastic_popfree")

PRESETS = {
    p.name: p
    for p in (
        Preset(
            "inria",
            "scalar",
            3,
            ViewFilter(),
            "graphdeco-inria/diff-gaussian-rasterization cuda_rasterizer/forward.cu (computeCov2D: +0.3); SIBR's "
            "gaussian viewer renders with it",
            "nothing: the scalar mode is this rasterizer",
        ),
        Preset(
            "gsplat-antialiased",
            "scalar",
            3,
            ViewFilter(0.3, compensate=True),
            "nerfstudio-project/gsplat gsplat/cuda/include/utils.cuh (add_blur), gsplat/rendering.py (eps2d=0.3, "
            "rasterize_mode='antialiased')",
            "gsplat's 3-sigma radius and 1/255 cutoff are the scalar mode's already",
        ),
        Preset(
            "supersplat",
            "scalar",
            3,
            SUPERSPLAT_FILTER,
            "playcanvas/engine src/scene/shader-lib/glsl/chunks/gsplat/vert/gsplatCorner.js (+0.3, 2 px early-out "
            "minPixelSize 2, quad 2 sqrt(2 lambda)), frag/gsplat.js (discard beyond |uv| = 1); playcanvas/supersplat "
            "src/ui/view-panel.ts (SH bands, default 3)",
            "normExp's kernel (exp(-4A) - e^-4) / (1 - e^-4), the lambda2 floor of 0.1, the 1024 px / viewport clamp, "
            "no 0.99 alpha cap, half-float colour and covariance, 8-bit output",
        ),
        Preset(
            "spark",
            "scalar",
            3,
            SPARK_FILTER,
            "sparkjsdev/spark src/SparkRenderer.ts (preBlurAmount 0.0, blurAmount 0.3, maxStdDev sqrt(8), "
            "sortRadial true), src/shaders/splatVertex.glsl, src/shaders/splatFragment.glsl, src/utils.ts "
            "(rgbMin 0, rgbMax 1)",
            "minAlpha 0.5/255, no 0.99 alpha cap, clipXY 1.4, the rest of the packed encoding (8-bit colour and "
            "opacity, log-encoded scales, float16 centres, quantised SH bands)",
        ),
        Preset(
            "supersplat-stochastic",
            "stochastic",
            3,
            SUPERSPLAT_FILTER,
            "playcanvas/engine src/scene/shader-lib/glsl/chunks/gsplat/frag/gsplat.js (opacityDither(alpha, "
            "id * 0.013): the splat id offsets the dither), src/scene/shader-lib/glsl/chunks/standard/frag/"
            "opacity-dither.js (discard when alpha < noise), the supersplat preset's filter and rules",
            "its blue-noise (or Bayer) dither texture and per-frame jitter (ours: stochastic.h's white-noise hash), "
            "the supersplat preset's list",
        ),
        Preset(
            "spark-stochastic",
            "stochastic",
            3,
            SPARK_FILTER,
            "sparkjsdev/spark src/shaders/splatFragment.glsl (STOCHASTIC: a hash of time, gl_FragCoord and the splat "
            "index; rand < alpha writes the colour opaque, else discard), the spark preset's filter and rules",
            "its PCG-style hash (ours is stochastic.h's), a time-based rather than frame-index seed, the spark "
            "preset's list",
        ),
        Preset(
            "antimatter15",
            "scalar",
            0,
            ViewFilter(0.0, dc_clamp=True, support=QUAD_SIGMAS),
            "antimatter15/splat main.js (no term added to cov2d; .splat colour only, clamped to 8 bits; quad "
            "2 sqrt(2 lambda), discard when A < -4)",
            "no 1/255 cutoff or 0.99 cap, 8-bit colour steps, opacity and quaternion, float16 covariance, the 1024 px "
            "axis clamp",
        ),
    )
}


TRAINED_SPECS = {THREEDGS: "scalar", ANTIALIASED: "preset:gsplat-antialiased", MIP_3D: "mip"}


def trained_spec(meta: dict) -> str | None:
    """The mode spec that renders a scene as it was trained (gbviewer.io.trained_as), None when unknown."""
    return TRAINED_SPECS.get(meta.get("trained_as", ""))


def differences(a: RenderSettings, b: RenderSettings) -> list[str]:
    """What differs between two settings' modes, presets and parameters, for a side-by-side label (a view filter
    other than the default is the scalar mode's only, so it differs only where one side is a scalar preset)."""
    out = [] if a.mode == b.mode else [f"mode {a.mode.label} vs {b.mode.label}"]
    out += a.view_filter.differences(b.view_filter)
    out += [] if a.sh_degree == b.sh_degree else [f"SH {a.sh_degree} vs {b.sh_degree}"]
    out += [] if a.supersample == b.supersample else [f"supersample {a.supersample} vs {b.supersample}"]
    return out
