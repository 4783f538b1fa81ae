"""Float64 reference of the stochastic modes' expectation (StochasticSplats' ST and ST-popfree rules,
native/include/gbv/stochastic.h): a sample keeps fragment i with probability alpha_i and shows the nearest kept one,
so over the keep decisions E[rgb] = sum_i c_i alpha_i prod_{j nearer} (1 - alpha_j) + bg prod_i (1 - alpha_i): alpha
blending in the variant's depth order without early termination. stochastic orders by centre depth (reference.py's
lists); stochastic_popfree per pixel by the depth, along the pixel's ray, of the plane through the splat's mean with
normal Sigma_v^-1 d (d: the direction of the ray through the mean). The second moment gives each sample's variance,
hence the sampling error of a mean over M independent samples. Written from those rules, independently of the
native code."""

from __future__ import annotations

import math

import numpy as np
from reference import _tile_lists
from reference_preprocess import MIN_ALPHA_3DGS, TILE, _get, camera_params, preprocess, quat_to_rotmat


def depth_planes(scene, cam, supersample: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Each splat's plane n . x = c in view space (n (N,3), c (N,)): through the view-space mean, n = Sigma_v^-1 d
    (times det Sigma_v > 0: the adjugate, defined for flat splats too)."""
    cp = camera_params(cam, supersample)
    R, t = cp["R"], cp["t"]
    mu = np.asarray(_get(scene, "means"), np.float64) @ R.T + t
    scales = np.asarray(_get(scene, "scales"), np.float64)
    f3d = _get(scene, "filter_3d")
    if f3d is not None:
        scales = np.sqrt(scales**2 + np.asarray(f3d, np.float64).reshape(-1, 1) ** 2)
    M = R @ quat_to_rotmat(_get(scene, "quats")) * scales[:, None, :]  # R Rq S
    sigma_v = M @ M.transpose(0, 2, 1)
    d = np.broadcast_to([0.0, 0.0, 1.0], mu.shape) if cp["ortho"] else mu
    a1, a2, a3 = sigma_v[..., 0], sigma_v[..., 1], sigma_v[..., 2]  # columns; adj = det * inverse, rows a_j x a_k
    adj = np.stack([np.cross(a2, a3), np.cross(a3, a1), np.cross(a1, a2)], -2)
    n = np.einsum("nij,nj->ni", adj, d)
    return n, np.einsum("ij,ij->i", n, mu)


def nearness(cp: dict, n: np.ndarray, c: float, pix: np.ndarray) -> np.ndarray:
    """Where the plane n . x = c meets each pixel's ray: 1/z (perspective) or -z (orthographic); larger is nearer."""
    u, v = (pix[:, 0] - cp["cx"]) / cp["fx"], (pix[:, 1] - cp["cy"]) / cp["fy"]
    if cp["ortho"]:
        return -(c - n[0] * u - n[1] * v) / n[2]
    return (n[0] * u + n[1] * v + n[2]) / c


def expectation(
    scene, cam, supersample: int = 1, background=(0.0, 0.0, 0.0), view_filter: dict | None = None, popfree: bool = False
):
    """Per sample of the N x N supersampled grid: (mean rgb (H,W,3), variance (H,W,3)) of one stochastic sample
    (`view_filter`: a preset's 2D filter, as reference.render_full_res takes it)."""
    pre = preprocess(scene, cam, "scalar", supersample, view_filter=view_filter)
    cp = camera_params(cam, supersample)
    planes = depth_planes(scene, cam, supersample) if popfree else None
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
            ids = lists(tx, ty)
            alpha = np.zeros((len(ids), len(pix)))
            for k, s in enumerate(ids):
                d = pix - pre["xy"][s]
                A, B, C = pre["conic"][s]
                power = -0.5 * (A * d[:, 0] ** 2 + C * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
                a = np.minimum(0.99, pre["opacity"][s] * np.exp(np.minimum(power, 0.0)))
                alpha[k] = np.where((power <= 0) & (a >= MIN_ALPHA_3DGS), a, 0.0)
            if popfree and len(ids):  # per pixel, nearest first; ties in list order
                with np.errstate(invalid="ignore", divide="ignore"):  # a splat without a plane is behind all
                    key = np.stack([nearness(cp, planes[0][s], planes[1][s], pix) for s in ids])
                key = np.where(np.isnan(key), -np.inf, key)
                order = np.argsort(-key, axis=0, kind="stable")
            else:
                order = np.broadcast_to(np.arange(len(ids))[:, None], alpha.shape)
            cols = pre["color"][ids] if len(ids) else np.zeros((0, 3))
            T = np.ones(len(pix))
            m = np.zeros((len(pix), 3))
            m2 = np.zeros((len(pix), 3))
            P = np.arange(len(pix))
            for k in range(len(ids)):
                a = alpha[order[k], P]
                w = (a * T)[:, None]  # P(this fragment is the nearest kept one)
                c = cols[order[k]]
                m += w * c
                m2 += w * c**2
                T *= 1.0 - a
            m += T[:, None] * bg
            m2 += T[:, None] * bg**2
            mean[i0:i1, j0:j1] = m.reshape(i1 - i0, j1 - j0, 3)
            second[i0:i1, j0:j1] = m2.reshape(i1 - i0, j1 - j0, 3)
    return mean, np.maximum(second - mean**2, 0.0)
