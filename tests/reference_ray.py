"""Float64 references of the per-pixel sorted modes (eval3d, stopthepop), written from the published rules and
independently of native/include/gbv/ray3d.h: the precision matrix is inverted directly (no whitening), the ray
maximum is the textbook closed form, and a brute-force 1D minimisation along the ray checks it.

- Ray maximum (3DGUT, nv-tlabs/3dgrut; gsplat docs/3dgut.md): along o + t d, t >= 0, the response
  exp(-(p - mu).P(p - mu) / 2) peaks at t* = d.P(mu - o) / d.P d (or at t = 0 when t* < 0).
- eval3d: alpha = min(0.99, o exp(-E/2)) at that maximum, skipped below 1/255; every splat in front of the near
  plane, no tile culling; each pixel in the order of max(t*, 0) (ties: the global order by centre depth).
- stopthepop (r4dl/StopThePop-Rasterization): 3DGS's 2D alpha (+0.3 dilation) of the splats whose 3DGS tile
  rectangle holds the pixel, in the global order by centre depth, dropped where t* < 0 (scales clamped to >= 1e-3
  for t*); K = 0 the exact per-pixel sort; K > 0 a queue of K fragments alone, sorted by t* (full: the nearest is
  blended before the next valid one goes in; the published hierarchy before it: reference_stopthepop.py).
Both composite as 3DGS: stop where T (1 - alpha) < 1e-4.
"""

from __future__ import annotations

import numpy as np
from reference import box_down
from reference_preprocess import MIN_ALPHA_3DGS, T_STOP, TILE, _get, camera_params, preprocess, quat_to_rotmat

STOPTHEPOP_MIN_SCALE = 1e-3


def precisions(scene, cp: dict, min_scale: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """View-space means (N,3) and precision matrices (Sigma^-1, (N,3,3)) of the scene's splats (3D filter applied,
    scales first raised to `min_scale`)."""
    means = np.asarray(_get(scene, "means"), np.float64)
    scales = np.maximum(np.asarray(_get(scene, "scales"), np.float64), min_scale)
    f3d = _get(scene, "filter_3d")
    if f3d is not None:
        scales = np.sqrt(scales**2 + np.asarray(f3d, np.float64).reshape(-1, 1) ** 2)
    Rq = quat_to_rotmat(np.asarray(_get(scene, "quats"), np.float64))
    M = cp["R"] @ Rq * scales[:, None, :]
    return means @ cp["R"].T + cp["t"], np.linalg.inv(M @ M.transpose(0, 2, 1))


def pixel_ray(cp: dict, px: float, py: float) -> tuple[np.ndarray, np.ndarray]:
    """Origin and direction (view space) of the ray through pixel position (px, py); d has z = 1."""
    u, v = (px - cp["cx"]) / cp["fx"], (py - cp["cy"]) / cp["fy"]
    if cp["ortho"]:
        return np.array([u, v, 0.0]), np.array([0.0, 0.0, 1.0])
    return np.zeros(3), np.array([u, v, 1.0])


def ray_maximum(P: np.ndarray, mu: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(E, t*) per splat: E the Mahalanobis distance squared at the maximum over t >= 0, t* = d.P(mu-o) / d.P d
    unclamped."""
    m = mu - o
    Pm = np.einsum("nij,nj->ni", P, m)
    b = Pm @ d
    a = np.einsum("i,nij,j->n", d, P, d)
    t = b / a
    mPm = np.einsum("ni,ni->n", m, Pm)
    return np.where(t > 0, mPm - b * b / a, mPm), t


def ray_maximum_brute(P: np.ndarray, mu: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """(E, t) of one splat by ternary search of the convex (p - mu).P(p - mu) over p = o + t d, t in [0, T]."""
    f = lambda t: float((o + t * d - mu) @ P @ (o + t * d - mu))  # noqa: E731
    lo, hi = 0.0, 10.0 * (np.linalg.norm(mu - o) + 1.0) / np.linalg.norm(d)
    for _ in range(300):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        lo, hi = (lo, b) if f(a) <= f(b) else (a, hi)
    t = 0.5 * (lo + hi)
    return f(t), t


def _composite(frags, color, bg) -> tuple[np.ndarray, float]:
    T, C = 1.0, np.zeros(3)
    for i, a in frags:
        test = T * (1.0 - a)
        if test < T_STOP:
            break
        C += color[i] * a * T
        T = test
    return C + T * np.asarray(bg, np.float64), 1.0 - T


def _queue_order(frags: list, depth: np.ndarray, queue: int) -> list:
    """Blend order of (index, alpha) fragments arriving in list order through a K-queue by depth (K = 0: exact)."""
    if queue == 0:
        return sorted(frags, key=lambda f: depth[f[0]])  # stable: arrival order among equal depths
    out, q = [], []
    for f in frags:
        if len(q) == queue:
            out.append(q.pop(0))
        k = len(q)
        while k > 0 and depth[q[k - 1][0]] > depth[f[0]]:
            k -= 1
        q.insert(k, f)
    return out + q


def render_sorted(scene, cam, mode: str, queue: int | None = None, supersample: int = 1, background=(0.0, 0.0, 0.0)):
    """(rgb (H,W,3), alpha (H,W)) of eval3d or stopthepop:queue, float64; `queue` (None: the mode's, exact for eval3d
    and 4 for stopthepop) is the per-pixel queue length, 0 the exact sort, 1 the centre-depth order."""
    queue = (0 if mode == "eval3d" else 4) if queue is None else queue
    assert mode in ("eval3d", "stopthepop"), mode
    cp = camera_params(cam, supersample)
    pre = preprocess(scene, cam, "scalar", supersample)
    mu, P = precisions(scene, cp, STOPTHEPOP_MIN_SCALE if mode == "stopthepop" else 0.0)
    if mode == "eval3d":
        cand = np.nonzero((pre["depth"] > cp["near"]) & (pre["opacity"] >= MIN_ALPHA_3DGS))[0]
    else:
        cand = np.nonzero(pre["keep"])[0]
    cand = cand[np.argsort(pre["depth"][cand], kind="stable")]
    W, H = cp["W"], cp["H"]
    rgb, alpha = np.zeros((H, W, 3)), np.zeros((H, W))
    for y in range(H):
        for x in range(W):
            ids = cand
            if mode == "stopthepop":
                r, tx, ty = pre["rect"][ids], x // TILE, y // TILE
                ids = ids[(r[:, 0] <= tx) & (tx < r[:, 1]) & (r[:, 2] <= ty) & (ty < r[:, 3])]
            px, py = x + 0.5, y + 0.5
            o, d = pixel_ray(cp, px, py)
            E, t = ray_maximum(P[ids], mu[ids], o, d)
            if mode == "eval3d":
                power, depth, ok = -0.5 * E, np.maximum(t, 0.0), np.ones(len(ids), bool)
            else:
                dx, dy = pre["xy"][ids, 0] - px, pre["xy"][ids, 1] - py
                a, b, c = pre["conic"][ids].T
                power, depth, ok = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy, t, t >= 0
            al = np.minimum(0.99, pre["opacity"][ids] * np.exp(np.minimum(power, 0.0)))
            ok &= (power <= 0) & (al >= MIN_ALPHA_3DGS)
            dep = dict(zip(ids.tolist(), depth.tolist()))
            frags = [(int(i), float(v)) for i, v in zip(ids[ok], al[ok])]
            rgb[y, x], alpha[y, x] = _composite(_queue_order(frags, dep, queue), pre["color"], background)
    if supersample > 1:
        return box_down(rgb, supersample), box_down(alpha, supersample)
    return rgb, alpha
