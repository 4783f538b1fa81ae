"""Difference and error images: the signed difference of two renders, a diverging colour map with its colour bar and
a robust default scale, and the references a render at sampling rate s is measured against:

- 'box': the x1 scalar render box-downsampled by k, for s = 1/k (the zoom-out reference of `gbviewer bench`; the x1
  view is the render's camera with k times the pixels per axis, so every reference pixel averages exactly the k x k
  x1 pixels inside the rendered pixel); none for rates above 1 or where 1/s is not an integer;
- 'dense': scalar with 8x8 supersampling at the render's own camera (any rate).

Used by the viewer's difference and error views (`app/difference/views.py`) and by `gbviewer compare --diff`.
"""

from __future__ import annotations

import numpy as np

from ..core.cancel import Cancellable
from ..model.camera import Camera, format_rate
from ..render import Mode, Renderer, RenderSettings
from .metrics import box_downsample, psnr, ssim, zoom_out_factor

REFERENCES = {"box": "x1 scalar box-downsampled", "dense": "scalar 8x8"}
DENSE_SUPERSAMPLE = 8
ROBUST_PERCENTILE = 99.0
MIN_SCALE = 1.0 / 255.0  # one 8-bit level: the scale of two equal images

# Crameri's 'berlin' (as in matplotlib >= 3.10) at 11 evenly spaced points from -1 to +1: light blue for negative,
# near-black at 0 (no difference reads as dark, like the viewer's background), light red for positive; its
# lightness grows with |x| on both sides.
DIVERGING = np.array(
    [
        [0.6211, 0.6902, 0.9995],
        [0.3853, 0.6517, 0.8794],
        [0.1979, 0.5013, 0.6490],
        [0.1241, 0.3213, 0.4151],
        [0.0686, 0.1530, 0.1958],
        [0.0983, 0.0470, 0.0347],
        [0.2145, 0.0627, 0.0014],
        [0.3815, 0.1256, 0.0437],
        [0.5889, 0.2889, 0.2136],
        [0.7929, 0.4821, 0.4433],
        [0.9999, 0.6801, 0.6800],
    ],
    np.float32,
)


def signed_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per pixel, the mean over R, G, B of a - b, both clipped to [0, 1] as they are shown and as PSNR sees them:
    > 0 where `a` is brighter. float32 (H, W).

    The mean over the channels (rather than luminance) weighs them as PSNR does; a change of opposite sign in two
    channels (a hue shift at equal brightness) partly cancels here, while PSNR still counts it."""
    a, b = np.clip(np.asarray(a, np.float32), 0, 1), np.clip(np.asarray(b, np.float32), 0, 1)
    if a.shape != b.shape:
        raise ValueError(f"difference of images of different sizes: {a.shape} and {b.shape}")
    return (a - b).mean(axis=2)


def robust_scale(d: np.ndarray, percentile: float = ROBUST_PERCENTILE) -> float:
    """The default colour-map scale of a difference: the `percentile`th percentile of |d| (a few outlier pixels do
    not wash the map out; beyond it the map clips), at least MIN_SCALE."""
    d = np.abs(np.asarray(d, np.float32))
    d = d[np.isfinite(d)]
    return max(MIN_SCALE, float(np.percentile(d, percentile))) if d.size else MIN_SCALE


def diverging(x: np.ndarray) -> np.ndarray:
    """Values in [-1, 1] (clipped; NaN as 0) to RGB in [0, 1], float32 (..., 3): DIVERGING, interpolated linearly."""
    x = (np.clip(np.nan_to_num(np.asarray(x, np.float32)), -1, 1) + 1) * 0.5 * (len(DIVERGING) - 1)
    i = np.minimum(x.astype(np.int32), len(DIVERGING) - 2)
    t = (x - i.astype(np.float32))[..., None]
    return DIVERGING[i] * (1 - t) + DIVERGING[i + 1] * t


def colour_difference(d: np.ndarray, scale: float) -> np.ndarray:
    """A signed difference as the diverging map shows it: -scale -> DIVERGING[0], 0 -> the middle, +scale ->
    DIVERGING[-1], clipped beyond."""
    return diverging(np.asarray(d, np.float32) / max(float(scale), 1e-12))


def colour_bar(width: int, height: int) -> np.ndarray:
    """The colour bar of `colour_difference`: (height, width, 3), from -scale in the first column to +scale in the
    last."""
    return np.broadcast_to(diverging(np.linspace(-1.0, 1.0, max(2, width)))[:width], (height, width, 3)).copy()


def format_scale(scale: float) -> str:
    """A scale as its colour bar's ends are labelled: '0.0831' (three significant digits)."""
    return f"{scale:.3g}"


def reference_settings(kind: str, settings: RenderSettings | None = None) -> RenderSettings:
    """What a reference of `kind` renders with: scalar, 1 or 8x8 samples, `settings`' background and SH degree."""
    if kind not in REFERENCES:
        raise ValueError(f"reference {kind!r}; expected one of {', '.join(REFERENCES)}")
    s = settings or RenderSettings()
    return RenderSettings(
        Mode.SCALAR, DENSE_SUPERSAMPLE if kind == "dense" else 1, s.background, s.sh_degree, threads=s.threads
    )


def reference_note(kind: str, rate: float) -> str:
    """Why a render at `rate` has no reference of `kind` ('' where it has one)."""
    if kind == "box" and zoom_out_factor(rate) is None:
        return f"no box reference at {format_rate(rate)} (only at 1/k): choose dense"
    return ""


def reference_image(
    renderer: Renderer,
    camera: Camera,
    rate: float,
    kind: str,
    settings: RenderSettings | None = None,
    cancel: Cancellable | None = None,
) -> np.ndarray | None:
    """The reference (H, W, 3) of a render at `camera`, the view at sampling rate `rate` (see the module's doc);
    None where `kind` has none at that rate (`reference_note` says why)."""
    ref = reference_settings(kind, settings)
    if kind == "dense":
        return renderer.render(camera, ref, cancel=cancel).rgb
    k = zoom_out_factor(rate)
    if k is None:
        return None
    x1 = renderer.render(camera.at_sampling_rate(k) if k > 1 else camera, ref, cancel=cancel).rgb
    return box_downsample(x1, k) if k > 1 else x1


def fidelity(rgb: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(PSNR in dB, SSIM) of a render against its reference (`metrics.psnr`, `metrics.ssim`)."""
    return psnr(rgb, reference), ssim(rgb, reference)
