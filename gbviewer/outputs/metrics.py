"""Image quality measures: box-downsampling (the zoom-out reference), PSNR, SSIM, temporal flicker."""

from __future__ import annotations

import math

import numpy as np

from ..core.extras import require

POP_THRESHOLD = 4.0 / 255.0  # a visible jump of one frame (see `flicker`)


def box_downsample(img: np.ndarray, k: int) -> np.ndarray:
    """Mean over k x k blocks (the multi-scale Blender construction); crops a ragged edge."""
    h, w = img.shape[0] // k, img.shape[1] // k
    return img[: h * k, : w * k].reshape(h, k, w, k, *img.shape[2:]).mean(axis=(1, 3))


def premultiplied_box_downsample(img: np.ndarray, k: int) -> np.ndarray:
    """Box-downsample by k of an (H, W, 3) RGB or (H, W, 4) straight-RGBA image that weights colour by alpha (the
    paper's appendix B.2): RGBA comes out premultiplied, sum(alpha c) / k^2 beside the mean alpha, which is what a
    sensor k times coarser records of the object over any background. Averaging straight colour instead (the
    original multi-scale Blender set) darkens edges, where transparent pixels carry colour 0."""
    if img.shape[-1] == 4:
        img = np.concatenate([img[..., :3] * img[..., 3:], img[..., 3:]], axis=-1)
    return box_downsample(img, k) if k > 1 else img


def composite(img: np.ndarray, background: tuple[float, float, float]) -> np.ndarray:
    """RGB of a `premultiplied_box_downsample` result over `background` (RGB passes through): c + (1 - alpha) bg."""
    if img.shape[-1] == 3:
        return img.astype(np.float32, copy=False)
    bg = np.asarray(background, np.float32)
    return (img[..., :3] + (1 - img[..., 3:]) * bg).astype(np.float32, copy=False)


def zoom_factor(rate: float) -> int | None:
    """The integer k of a sampling rate 1/k or k (1 for rate 1), or None where there is none (rate 1/3.7)."""
    k = round(1 / rate) if rate < 1 else round(rate)
    return k if k >= 1 and math.isclose(k, 1 / rate if rate < 1 else rate, rel_tol=1e-6) else None


def zoom_out_factor(rate: float) -> int | None:
    """The k of a zoom-out rate 1/k (1 at x1) whose reference is the x1 render box-downsampled by k; None for rates
    above 1 and rates whose 1/rate is not an integer."""
    return zoom_factor(rate) if rate <= 1 else None


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of images clipped to [0, 1]."""
    mse = float(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2))
    return math.inf if mse == 0 else -10.0 * math.log10(mse)


def reference_psnr(reference_x1: np.ndarray, rgb: np.ndarray, rate: float) -> float | None:
    """PSNR of a render at rate 1/k against the x1 render box-downsampled by k (the zoom-out reference); None
    where there is none (rates > 1, 1/rate not an integer, sizes that do not divide)."""
    k = zoom_out_factor(rate)
    if k is None:
        return None
    ref = box_downsample(reference_x1, k) if k > 1 else reference_x1
    return psnr(rgb, ref) if ref.shape == rgb.shape else None


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM (scikit-image, Gaussian-weighted as in Wang et al.) of RGB images clipped to [0, 1]; NaN for images
    smaller than its 11 x 11 window."""
    structural_similarity = require("eval", "skimage.metrics", "SSIM").structural_similarity
    a, b = np.clip(a, 0, 1).astype(np.float64), np.clip(b, 0, 1).astype(np.float64)
    if min(a.shape[:2]) < 11:  # the 11x11 Gaussian window (sigma 1.5) must fit
        return float("nan")
    return float(
        structural_similarity(
            a, b, channel_axis=2, data_range=1.0, gaussian_weights=True, sigma=1.5, use_sample_covariance=False
        )
    )


def flicker(frames: list[np.ndarray]) -> tuple[float, float]:
    """Popping along a slow camera path: frames I_0..I_{F-1} (clipped to [0, 1]) rendered at equal small steps.

    flicker = 255 x mean over t = 1..F-2, pixels and channels of |I_{t+1} - 2 I_t + I_{t-1}|, in 8-bit levels.
    Smooth motion at a constant step changes a pixel by about the same amount every frame, so its second
    difference is O(step^2); a sort-order swap (popping) is a step in one frame, which shows up at full size in the
    second difference of two consecutive t. pops = fraction of (pixel, t) whose largest channel |second difference|
    exceeds POP_THRESHOLD (4/255, a visible jump)."""
    if len(frames) < 3:
        return float("nan"), float("nan")
    f = np.clip(np.stack(frames).astype(np.float64), 0.0, 1.0)
    d2 = np.abs(f[2:] - 2.0 * f[1:-1] + f[:-2])
    return float(255.0 * d2.mean()), float((d2.max(axis=-1) > POP_THRESHOLD).mean())
