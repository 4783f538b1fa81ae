"""The scalar mode's 2D filter, as viewer presets set it (native/include/gbv/view_filter.h, gbv::OitParams' filter
fields): what other viewers add to a splat's projected covariance, whether they compensate its opacity, and which
small splats they drop. Imports nothing of the render layer, so that `types` can hold one."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..errors import InvalidValue, RenderError
from ..validate import real

DILATION_3DGS = 0.3  # gbv::DILATION_3DGS (px^2)


@dataclass(frozen=True)
class ViewFilter:
    """Sigma' = Sigma + pre_dilation I (never compensated); Sigma'' = Sigma' + dilation I, and with `compensate` the
    opacity times sqrt(max(0, det Sigma' / det Sigma'')); culled when the larger eigenvalue of Sigma'' is below
    `cull_lambda` (px^2). The default is 3DGS's +0.3 px^2, nothing else."""

    dilation: float = DILATION_3DGS
    pre_dilation: float = 0.0
    compensate: bool = False
    cull_lambda: float = 0.0

    def __post_init__(self) -> None:
        """Each number finite, >= 0 and a float32 (the kernels take float32); a bad one is a one-line RenderError."""
        for name in ("dilation", "pre_dilation", "cull_lambda"):
            try:
                object.__setattr__(self, name, real(getattr(self, name), name, lo=0.0, f32=True))
            except InvalidValue as exc:
                raise RenderError(str(exc)) from None
        object.__setattr__(self, "compensate", bool(self.compensate))

    @property
    def is_default(self) -> bool:
        return self == ViewFilter()

    def native(self) -> np.ndarray:
        """The native renderers' `view_filter` argument: float32 [dilation, pre_dilation, cull_lambda, compensate]."""
        return np.array([self.dilation, self.pre_dilation, self.cull_lambda, float(self.compensate)], np.float32)

    def describe(self) -> str:
        """'+0.3 px^2, opacity compensated, cull lambda_max < 0.5 px^2', the parts that are set."""
        parts = ([f"+{self.pre_dilation:g} px^2 uncompensated"] if self.pre_dilation else []) + [
            f"+{self.dilation:g} px^2" + (" opacity compensated" if self.compensate else "")]
        if self.cull_lambda:
            parts.append(f"cull lambda_max < {self.cull_lambda:g} px^2")
        return ", ".join(parts)

    def differences(self, other: "ViewFilter") -> list[str]:
        """'dilation 0.3 vs 0' for each field that differs."""
        return [f"{f.name} {getattr(self, f.name):g} vs {getattr(other, f.name):g}" for f in fields(self)
                if getattr(self, f.name) != getattr(other, f.name)]
