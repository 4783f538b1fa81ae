"""Float64 reference of the stochastic mode's expectation (StochasticSplats' ST rule, native/include/gbv/stochastic.h):
a sample keeps fragment i with probability alpha_i and shows the nearest kept one (centre depth), so over the keep
decisions E[rgb] = sum_i c_i alpha_i prod_{j<i} (1 - alpha_j) + bg prod_i (1 - alpha_i): alpha blending in depth order
without early termination. Its second moment gives each sample's variance, hence the sampling error of a mean over M
independent samples. Written from that rule, independently of the native code; the lists are reference.py's."""

from __future__ import annotations

import math

import numpy as np

from reference import _tile_lists
from reference_preprocess import MIN_ALPHA_3DGS, TILE, preprocess


def expectation(scene, cam, supersample: int = 1, background=(0.0, 0.0, 0.0), view_filter: dict | None = None):
    """Per sample of the N x N supersampled grid: (mean rgb (H,W,3), variance (H,W,3)) of one stochastic sample
    (`view_filter`: a preset's 2D filter, as reference.render_full_res takes it)."""
    pre = preprocess(scene, cam, "scalar", supersample, view_filter=view_filter)
    W, H = pre["W"], pre["H"]
    bg = np.asarray(background, np.float64)
    mean = np.zeros((H, W, 3))
    second = np.zeros((H, W, 3))
    lists, _ = _tile_lists(pre, "scalar", cam, supersample)
    for ty in range(math.ceil(H / TILE)):
        for tx in range(math.ceil(W / TILE)):
            i0, i1, j0, j1 = ty * TILE, min(H, (ty + 1) * TILE), tx * TILE, min(W, (tx + 1) * TILE)
            ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1), indexing="ij")
            pix = np.stack([jj.ravel() + 0.5, ii.ravel() + 0.5], -1)
            T = np.ones(len(pix))
            m = np.zeros((len(pix), 3))
            m2 = np.zeros((len(pix), 3))
            for s in lists(tx, ty):
                d = pix - pre["xy"][s]
                A, B, C = pre["conic"][s]
                power = -0.5 * (A * d[:, 0] ** 2 + C * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
                alpha = np.minimum(0.99, pre["opacity"][s] * np.exp(np.minimum(power, 0.0)))
                alpha = np.where((power <= 0) & (alpha >= MIN_ALPHA_3DGS), alpha, 0.0)
                w = (alpha * T)[:, None]  # P(this fragment is the nearest kept one)
                m += w * pre["color"][s]
                m2 += w * pre["color"][s] ** 2
                T *= 1.0 - alpha
            m += T[:, None] * bg
            m2 += T[:, None] * bg ** 2
            mean[i0:i1, j0:j1] = m.reshape(i1 - i0, j1 - j0, 3)
            second[i0:i1, j0:j1] = m2.reshape(i1 - i0, j1 - j0, 3)
    return mean, np.maximum(second - mean ** 2, 0.0)
