"""The scalar mode's 2D filter and rules, as viewer presets set them (native/include/gbv/view_filter.h, gbv::OitParams'
filter fields): what other viewers add to a splat's projected covariance, whether they compensate its opacity, which
small splats they drop, and what they do beyond 3DGS's rasterizer: a base colour clamped to [0, 1] (an 8-bit
encoding), a support cut at a Mahalanobis radius (their quad) and a sort by distance from the eye. Imports nothing of
the render layer, so that `types` can hold one."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..core.errors import InvalidValue, RenderError
from ..core.validate import real

DILATION_3DGS = 0.3  # gbv::DILATION_3DGS (px^2)


@dataclass(frozen=True)
class ViewFilter:
    """Sigma' = Sigma + pre_dilation I (never compensated); Sigma'' = Sigma' + dilation I, and with `compensate` the
    opacity times sqrt(max(0, det Sigma' / det Sigma'')); culled when the larger eigenvalue of Sigma'' is below
    `cull_lambda` (px^2). `dc_clamp`: the base colour 0.5 + C0 dc clamped to [0, 1] before the higher SH bands are
    added; `support` (sigmas, 0: none): alpha 0 where the pixel's Mahalanobis distance exceeds it; `sort_radial`:
    splats ordered by distance from the eye instead of view-space z (perspective cameras). The default is 3DGS's
    +0.3 px^2, nothing else."""

    dilation: float = DILATION_3DGS
    pre_dilation: float = 0.0
    compensate: bool = False
    cull_lambda: float = 0.0
    dc_clamp: bool = False
    support: float = 0.0
    sort_radial: bool = False

    def __post_init__(self) -> None:
        """Each number finite, >= 0 and a float32 (the kernels take float32); a bad one is a one-line RenderError."""
        for name in ("dilation", "pre_dilation", "cull_lambda", "support"):
            try:
                object.__setattr__(self, name, real(getattr(self, name), name, lo=0.0, f32=True))
            except InvalidValue as exc:
                raise RenderError(str(exc)) from None
        for name in ("compensate", "dc_clamp", "sort_radial"):
            object.__setattr__(self, name, bool(getattr(self, name)))

    @property
    def is_default(self) -> bool:
        return self == ViewFilter()

    def native(self) -> np.ndarray:
        """The native renderers' `view_filter` argument: float32 [dilation, pre_dilation, cull_lambda, compensate,
        dc_clamp, support, sort_radial]."""
        return np.array(
            [
                self.dilation,
                self.pre_dilation,
                self.cull_lambda,
                float(self.compensate),
                float(self.dc_clamp),
                self.support,
                float(self.sort_radial),
            ],
            np.float32,
        )

    @property
    def stage_rules(self) -> int:
        """gbv::stage_rules' bits for the scalar mode: 1 dc_clamp, 2 sort_radial."""
        return int(self.dc_clamp) | 2 * int(self.sort_radial)

    def describe(self) -> str:
        """'+0.3 px^2, opacity compensated, cull lambda_max < 0.5 px^2', the parts that are set."""
        parts = ([f"+{self.pre_dilation:g} px^2 uncompensated"] if self.pre_dilation else []) + [
            f"+{self.dilation:g} px^2" + (" opacity compensated" if self.compensate else "")
        ]
        if self.cull_lambda:
            parts.append(f"cull lambda_max < {self.cull_lambda:g} px^2")
        parts += (
            ["base colour clamped to [0, 1]"] * self.dc_clamp
            + [f"support {self.support:.3g} sigma"] * (self.support > 0)
            + ["radial sort"] * self.sort_radial
        )
        return ", ".join(parts)

    def differences(self, other: "ViewFilter") -> list[str]:
        """'dilation 0.3 vs 0' for each field that differs."""
        return [
            f"{f.name} {getattr(self, f.name):g} vs {getattr(other, f.name):g}"
            for f in fields(self)
            if getattr(self, f.name) != getattr(other, f.name)
        ]
