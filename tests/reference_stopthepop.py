"""Float64 reference of StopThePop's hierarchical resort as published (r4dl/StopThePop-Rasterization:
cuda_rasterizer/stopthepop/hierarchical_render.cuh, sortGaussiansRayHierarchicaEvaluation; the per-tile key of
stopthepop_common.cuh, duplicateWithKeys_extended with PER_TILE_DEPTH_MAXPOS and max_contrib_power_rect_gaussian_float;
the queue sizes of r4dl/StopThePop configs/hierarchical.json: 4x4 64, 2x2 8, per pixel 4, hierarchical_4x4_culling on),
written from those rules as a chain of streams, independently of native/include/gbv/resort.h's walk.

Pixel coordinates: pixel i's centre is i + 0.5 (the published kernel's integer centres, shifted). The fragments are
3DGS's 2D splats (conic with +0.3, scalar's tile rectangles and centre-depth order) as in reference_ray.py.
1. tile: the tile's splats (centre-depth order) stably sorted by the depth along the unit ray through the point of the
   tile's pixel-centre rectangle the rectangle rule picks, plus 8, floored at 0 (in float64: no ties by rounding).
2. 4x4: per load of 32 entries, the entries whose alpha at the 4x4 rectangle's picked point is >= 1/255 are merged
   into the queue by the depth at the 4x4 centre ray (old entries first on ties); while it holds more than 32 its 16
   nearest go on, in groups of 4; at the end the rest, in groups of 4.
3. 2x2: the first group is held; each later group, merged with the held ones by the depth at the 2x2 centre ray (held
   first on ties, the group's own ties in arrival order), gives its 4 nearest and holds the rest; at the end the held.
4. pixel: each arriving entry first blends the queue's nearest if the queue holds K, then goes in (behind equal
   depths) when its fragment is valid at the pixel (t* >= 0, power <= 0, alpha >= 1/255); the rest in order.
With `hierarchy=False` only stage 4 runs, over the centre-depth list (the per-pixel queue alone)."""

from __future__ import annotations

import numpy as np
from reference import box_down
from reference_preprocess import MIN_ALPHA_3DGS, TILE, camera_params, preprocess
from reference_ray import (
    STOPTHEPOP_MIN_SCALE,
    _composite,
    pixel_ray,
    precisions,
    ray_maximum,
)

KEY_OFFSET = 8.0
LOAD, PULL, GROUP = 32, 16, 4


def rect_point(xy: np.ndarray, conic: np.ndarray, x0: float, y0: float, w: float, h: float):
    """The published rectangle rule: per splat, the point of [x0, x0 + w] x [y0, y0 + h] it takes as the Gaussian's
    largest, and the conic's half quadratic form (-log of the Gaussian) there."""
    a, b, c = conic.T
    mx, my = xy[:, 0], xy[:, 1]
    left, right, above, below = x0 > mx, mx > x0 + w, y0 > my, my > y0 + h
    out_x, out_y = left | right, above | below
    px, py = np.where(left, x0, x0 + w), np.where(above, y0, y0 + h)
    dx, dy = np.where(x0 - mx < 0, -w, w), np.where(y0 - my < 0, -h, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.nan_to_num(np.clip((dx * a * (mx - px) + dx * b * (my - py)) / (w * w * a), 0, 1)) * out_y
        ty = np.nan_to_num(np.clip((dy * b * (mx - px) + dy * c * (my - py)) / (h * h * c), 0, 1)) * out_x
    out = out_x | out_y
    qx, qy = np.where(out, px + tx * dx, mx), np.where(out, py + ty * dy, my)
    ex, ey = mx - qx, my - qy
    return qx, qy, np.where(out, 0.5 * (a * ex * ex + c * ey * ey) + b * ex * ey, 0.0)


def _depth_at(ids, P, mu, cp, qx, qy, unit=False):
    """t* of the splats `ids` along the ray through (qx, qy) (per splat when arrays); unit: along the unit ray."""
    if np.ndim(qx) == 0:
        return ray_maximum(P[ids], mu[ids], *pixel_ray(cp, qx, qy))[1]
    t = np.empty(len(ids))
    for k, i in enumerate(ids):
        o, d = pixel_ray(cp, qx[k], qy[k])
        t[k] = ray_maximum(P[i : i + 1], mu[i : i + 1], o, d)[1][0] * (np.linalg.norm(d) if unit else 1.0)
    return t


def _tile_stream(ids, pre, P, mu, cp, tx, ty) -> list[int]:
    x0, y0 = tx * TILE + 0.5, ty * TILE + 0.5
    qx, qy, _ = rect_point(pre["xy"][ids], pre["conic"][ids], x0, y0, TILE - 1.0, TILE - 1.0)
    key = np.maximum(_depth_at(ids, P, mu, cp, qx, qy, unit=True) + KEY_OFFSET, 0.0)
    return ids[np.argsort(key, kind="stable")].tolist()


def _groups_4x4(order, pre, P, mu, cp, x4, y4) -> list[list[int]]:
    ids = np.asarray(order, np.int64)
    if len(ids) == 0:
        return []
    _, _, power = rect_point(pre["xy"][ids], pre["conic"][ids], x4 + 0.5, y4 + 0.5, 3.0, 3.0)
    kept = np.minimum(0.99, pre["opacity"][ids] * np.exp(-power)) >= MIN_ALPHA_3DGS
    depth = dict(zip(ids.tolist(), _depth_at(ids, P, mu, cp, x4 + 2.0, y4 + 2.0)))
    tail, out = [], []
    for base in range(0, len(ids), LOAD):
        tail = sorted(
            tail + [int(i) for i, k in zip(ids[base : base + LOAD], kept[base : base + LOAD]) if k],
            key=depth.__getitem__,
        )
        while len(tail) > LOAD:
            out += [tail[k : k + GROUP] for k in range(0, PULL, GROUP)]
            tail = tail[PULL:]
    return out + [tail[k : k + GROUP] for k in range(0, len(tail), GROUP)]


def _stream_2x2(groups, P, mu, cp, x2, y2) -> list[int]:
    ids = np.asarray(sorted({i for g in groups for i in g}), np.int64)
    depth = dict(zip(ids.tolist(), _depth_at(ids, P, mu, cp, x2 + 1.0, y2 + 1.0))) if len(ids) else {}
    held, out = None, []
    for g in groups:
        merged = sorted((held or []) + sorted(g, key=depth.__getitem__), key=depth.__getitem__)
        if held is None:
            held = merged
        else:
            out, held = out + merged[:GROUP], merged[GROUP:]
    return out + (held or [])


def _pixel_order(arrivals, frag: dict, queue: int) -> list:
    """Stage 4: (index, alpha) in blend order; frag maps the valid fragments' index to (depth, alpha)."""
    out, q = [], []
    for i in arrivals:
        if len(q) == queue:
            out.append(q.pop(0))
        if i in frag:
            k = len(q)
            while k > 0 and frag[q[k - 1]][0] > frag[i][0]:
                k -= 1
            q.insert(k, i)
    return [(i, frag[i][1]) for i in out + q]


def render_hierarchical(
    scene,
    cam,
    queue: int = 4,
    supersample: int = 1,
    background=(0.0, 0.0, 0.0),
    hierarchy: bool = True,
    orders: dict | None = None,
):
    """(rgb (H,W,3), alpha (H,W)) of stopthepop:queue, float64 (queue > 0). `orders`: filled with each pixel's blend
    order (splat indices) when given."""
    cp = camera_params(cam, supersample)
    pre = preprocess(scene, cam, "scalar", supersample)
    mu, P = precisions(scene, cp, STOPTHEPOP_MIN_SCALE)
    cand = np.nonzero(pre["keep"])[0]
    cand = cand[np.argsort(pre["depth"][cand], kind="stable")]
    W, H = cp["W"], cp["H"]
    rgb, alpha = np.zeros((H, W, 3)), np.zeros((H, W))
    r = pre["rect"][cand]
    for ty in range((H + TILE - 1) // TILE):
        for tx in range((W + TILE - 1) // TILE):
            ids = cand[(r[:, 0] <= tx) & (tx < r[:, 1]) & (r[:, 2] <= ty) & (ty < r[:, 3])]
            order = _tile_stream(ids, pre, P, mu, cp, tx, ty) if hierarchy else ids.tolist()
            streams: dict = {}
            for y in range(ty * TILE, min(H, ty * TILE + TILE)):
                for x in range(tx * TILE, min(W, tx * TILE + TILE)):
                    arrivals = order
                    if hierarchy:
                        x4, y4, x2, y2 = x - x % 4, y - y % 4, x - x % 2, y - y % 2
                        if (4, x4, y4) not in streams:
                            streams[4, x4, y4] = _groups_4x4(order, pre, P, mu, cp, x4, y4)
                        if (2, x2, y2) not in streams:
                            streams[2, x2, y2] = _stream_2x2(streams[4, x4, y4], P, mu, cp, x2, y2)
                        arrivals = streams[2, x2, y2]
                    frag = _fragments(np.asarray(arrivals, np.int64), pre, P, mu, cp, x + 0.5, y + 0.5)
                    blend = _pixel_order(arrivals, frag, queue)
                    if orders is not None:
                        orders[(x, y)] = [i for i, _ in blend]
                    rgb[y, x], alpha[y, x] = _composite(blend, pre["color"], background)
    if supersample > 1:
        return box_down(rgb, supersample), box_down(alpha, supersample)
    return rgb, alpha


def _fragments(ids, pre, P, mu, cp, px, py) -> dict:
    if len(ids) == 0:
        return {}
    _, t = ray_maximum(P[ids], mu[ids], *pixel_ray(cp, px, py))
    dx, dy = pre["xy"][ids, 0] - px, pre["xy"][ids, 1] - py
    a, b, c = pre["conic"][ids].T
    power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    al = np.minimum(0.99, pre["opacity"][ids] * np.exp(np.minimum(power, 0.0)))
    ok = (t >= 0) & (power <= 0) & (al >= MIN_ALPHA_3DGS)
    return {int(i): (float(d), float(v)) for i, d, v, k in zip(ids, t, al, ok) if k}
