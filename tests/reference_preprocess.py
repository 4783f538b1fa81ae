"""The reference renderer's preprocess (see reference.py): constants, SH colours, projection, per-splat and
per-cell (Duplex-GS) screen-space data, in float64."""

from __future__ import annotations

import math

import numpy as np

from gbviewer.model.camera import NEAR_PLANE
from gbviewer.model.scene import SH_C0

TILE = 16
MIN_ALPHA_3DGS = 1.0 / 255.0
MIN_ALPHA_GB = 1.0 / 256.0
T_STOP = 1e-4
GB_EXTENT = math.sqrt(-2.0 * math.log(MIN_ALPHA_GB))  # 3.33021844...
GB_MIN_UV = 0.1
GB_MAX_UV = 1e6
GB_MIN_VAR = 0.001

MODES = ("scalar", "mip", "analytic", "gaussian_blending")
OIT_MODES = ("wsr", "duplex")
DUPLEX_STOP = 0.01  # CUMMULT_THRESHOLD (docs/modes.md#duplex)
WSR_EMPTY = 1e-4
WSR_TERM_MAX = 64.0  # wsr: alpha and each colour term are capped here (the renderer's int64 fixed-point bound)

# Spherical-harmonics constants of 3DGS (docs/modes.md#colour).
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)


def _get(scene, name):
    if isinstance(scene, dict):
        return scene.get(name)
    return getattr(scene, name)


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions (w,x,y,z) -> (N,3,3) rotation matrices (zero quaternion -> identity)."""
    q = np.asarray(q, np.float64)
    n = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(n > 1e-12, q / np.maximum(n, 1e-300), np.array([1.0, 0.0, 0.0, 0.0]))
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def sh_to_rgb(sh: np.ndarray, dirs: np.ndarray, dc_clamp: bool = False) -> np.ndarray:
    """Evaluate the 3DGS real SH basis; sh (N,K,3), dirs (N,3) unit. Returns max(0, sum + 0.5); with dc_clamp the
    base colour 0.5 + C0 dc is clamped to [0, 1] before the higher bands are added."""
    k = sh.shape[1]
    x, y, z = (dirs[:, i : i + 1] for i in range(3))
    res = SH_C0 * sh[:, 0] + 0.5
    if dc_clamp:
        res = np.clip(res, 0.0, 1.0)
    if k > 1:
        res = res - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        res = (
            res
            + SH_C2[0] * xy * sh[:, 4]
            + SH_C2[1] * yz * sh[:, 5]
            + SH_C2[2] * (2 * zz - xx - yy) * sh[:, 6]
            + SH_C2[3] * xz * sh[:, 7]
            + SH_C2[4] * (xx - yy) * sh[:, 8]
        )
    if k > 9:
        res = (
            res
            + SH_C3[0] * y * (3 * xx - yy) * sh[:, 9]
            + SH_C3[1] * xy * z * sh[:, 10]
            + SH_C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
            + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
            + SH_C3[4] * x * (4 * zz - xx - yy) * sh[:, 13]
            + SH_C3[5] * z * (xx - yy) * sh[:, 14]
            + SH_C3[6] * x * (xx - 3 * yy) * sh[:, 15]
        )
    return np.maximum(res, 0.0)


def camera_params(cam, supersample: int = 1) -> dict:
    """Camera as float64, with the float32 rounding of R and t that the native call applies."""
    n = int(supersample)
    return dict(
        W=int(cam.width) * n,
        H=int(cam.height) * n,
        fx=float(np.float32(cam.fx)) * n,
        fy=float(np.float32(cam.fy)) * n,
        cx=float(np.float32(cam.cx)) * n,
        cy=float(np.float32(cam.cy)) * n,
        R=np.asarray(cam.R, np.float32).astype(np.float64),
        t=np.asarray(cam.t, np.float32).astype(np.float64),
        near=float(getattr(cam, "near", NEAR_PLANE)),
        ortho=getattr(cam, "projection", "perspective") == "orthographic",
    )


def project(cp: dict, view: np.ndarray, Sigma: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Screen positions (N,2) and EWA 2D covariances J W Sigma W^T J^T (N,2,2) of view-space points (N,3) with
    world covariances Sigma (N,3,3); rows not in `keep` are finite garbage. Perspective: J = [[fx/Z, 0, -fx X/Z^2],
    [0, fy/Z, -fy Y/Z^2]] with X/Z, Y/Z clamped to 1.3x the frustum (J only); orthographic: J = diag(fx, fy)."""
    W, H, fx, fy, cx, cy, R = (cp[k] for k in ("W", "H", "fx", "fy", "cx", "cy", "R"))
    X, Y, Z = view.T
    J = np.zeros((len(view), 2, 3))
    if cp["ortho"]:
        J[:, 0, 0], J[:, 1, 1] = fx, fy
        xy = np.stack([fx * X + cx, fy * Y + cy], -1)
    else:
        Zs = np.where(keep, Z, 1.0)  # avoid division warnings for culled points
        tan_x, tan_y = 0.5 * W / fx, 0.5 * H / fy
        tx = np.clip(X / Zs, -(cx / fx + 0.3 * tan_x), (W - cx) / fx + 0.3 * tan_x) * Zs
        ty = np.clip(Y / Zs, -(cy / fy + 0.3 * tan_y), (H - cy) / fy + 0.3 * tan_y) * Zs
        J[:, 0, 0] = fx / Zs
        J[:, 0, 2] = -fx * tx / Zs**2
        J[:, 1, 1] = fy / Zs
        J[:, 1, 2] = -fy * ty / Zs**2
        xy = np.stack([fx * X / Zs + cx, fy * Y / Zs + cy], -1)
    T = J @ R  # J W
    return xy, T @ Sigma @ T.transpose(0, 2, 1)


def view_dirs(cp: dict, means: np.ndarray) -> np.ndarray:
    """Unit SH view directions (N,3): from the camera centre to each mean, or the forward axis (orthographic)."""
    R, t = cp["R"], cp["t"]
    if cp["ortho"]:
        return np.tile(R[2] / np.linalg.norm(R[2]), (len(means), 1))
    d = means - (-R.T @ t)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)


def _sh_raw(c: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """A 1-channel SH (N,K) at unit dirs (N,3): the raw sum (sort-free GS's v_i, docs/modes.md#wsr)."""
    k = c.shape[1]
    x, y, z = dirs.T
    res = SH_C0 * c[:, 0]
    if k > 1:
        res = res - SH_C1 * y * c[:, 1] + SH_C1 * z * c[:, 2] - SH_C1 * x * c[:, 3]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        res = (
            res
            + SH_C2[0] * xy * c[:, 4]
            + SH_C2[1] * yz * c[:, 5]
            + SH_C2[2] * (2 * zz - xx - yy) * c[:, 6]
            + SH_C2[3] * xz * c[:, 7]
            + SH_C2[4] * (xx - yy) * c[:, 8]
        )
    if k > 9:
        res = (
            res
            + SH_C3[0] * y * (3 * xx - yy) * c[:, 9]
            + SH_C3[1] * xy * z * c[:, 10]
            + SH_C3[2] * y * (4 * zz - xx - yy) * c[:, 11]
            + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * c[:, 12]
            + SH_C3[4] * x * (4 * zz - xx - yy) * c[:, 13]
            + SH_C3[5] * z * (xx - yy) * c[:, 14]
            + SH_C3[6] * x * (xx - 3 * yy) * c[:, 15]
        )
    return res


def preprocess(
    scene, cam, mode: str, supersample: int = 1, oit: dict | None = None, view_filter: dict | None = None
) -> dict:
    """Per-splat screen-space quantities (float64). Arrays are indexed like the scene; `keep` marks survivors.

    wsr / duplex (docs/modes.md#wsr, #duplex): as scalar (+0.3, radius 3 sqrt(lambda_max)), and the opacity becomes
    o * v * (1 - z/sigma if depth_correct), with v the view-weight SH (raw) or 1; culled when z >= sigma
    (depth_correct) or v * correction <= 0.

    view_filter (scalar; a viewer preset's rule as its viewer's code states it, gbviewer/render/presets.py):
    dict(dilation, pre_dilation, compensate, cull_lambda): Sigma' = Sigma + pre_dilation I, Sigma'' = Sigma' +
    dilation I replace the +0.3; compensate multiplies the opacity by sqrt(max(0, det Sigma' / det Sigma'')); a
    splat whose larger eigenvalue of Sigma'' is below cull_lambda is dropped; dc_clamp clamps the base colour
    (sh_to_rgb); support > 0 gives no alpha beyond that Mahalanobis radius (`min_power` = -support^2 / 2, the blend's
    cut); sort_radial orders by the distance from the eye (perspective), the `depth` it returns."""
    assert mode in MODES + OIT_MODES, mode
    cp = camera_params(cam, supersample)
    W, H, R, t = (cp[k] for k in ("W", "H", "R", "t"))
    means = np.asarray(_get(scene, "means"), np.float64)
    scales = np.asarray(_get(scene, "scales"), np.float64)
    quats = np.asarray(_get(scene, "quats"), np.float64)
    opac = np.asarray(_get(scene, "opacities"), np.float64).reshape(-1).copy()
    sh = np.asarray(_get(scene, "sh"), np.float64)
    f3d = _get(scene, "filter_3d")
    n = means.shape[0]

    view = means @ R.T + t
    Z = view[:, 2]
    keep = Z > cp["near"]

    # Mip-Splatting 3D filter (every mode when present)
    if f3d is not None:
        f2 = np.asarray(f3d, np.float64).reshape(-1) ** 2
        s2 = scales**2
        opac = opac * np.sqrt(np.prod(s2, axis=1) / np.prod(s2 + f2[:, None], axis=1))
        scales = np.sqrt(s2 + f2[:, None])

    Rq = quat_to_rotmat(quats)
    M = Rq * scales[:, None, :]  # R S
    Sigma = M @ M.transpose(0, 2, 1)
    xy, cov = project(cp, view, Sigma, keep)
    dirs = view_dirs(cp, means)
    a, b, c = cov[:, 0, 0].copy(), cov[:, 0, 1].copy(), cov[:, 1, 1].copy()

    if mode == "scalar" and view_filter is not None:
        a += view_filter["pre_dilation"]
        c += view_filter["pre_dilation"]
        det0 = a * c - b * b
        a += view_filter["dilation"]
        c += view_filter["dilation"]
        if view_filter["compensate"]:
            opac = opac * np.sqrt(np.maximum(0.0, det0 / (a * c - b * b)))
        lam_max = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)
        keep &= lam_max >= view_filter["cull_lambda"]
    elif mode in ("scalar",) + OIT_MODES:
        a += 0.3
        c += 0.3
    if mode in OIT_MODES:
        if isinstance(scene, dict):
            vw = scene.get("view_weight_sh")
        else:
            vw = scene.oit.view_weight_sh if scene.oit is not None else None
        w = _sh_raw(np.asarray(vw, np.float64), dirs) if vw is not None else np.ones(n)
        if oit["depth_correct"]:
            keep &= Z < oit["sigma"]
            w = w * (1.0 - Z / oit["sigma"])
        keep &= w > 0
        opac = opac * w
    elif mode == "mip":
        det0 = np.maximum(1e-6, a * c - b * b)
        a += 0.1
        c += 0.1
        det1 = np.maximum(1e-6, a * c - b * b)
        coef = np.sqrt(det0 / (det1 + 1e-6) + 1e-6)
        coef = np.where((det0 <= 1e-6) | (det1 <= 1e-6), 0.0, coef)
        opac = opac * coef
    det = a * c - b * b
    min_alpha = MIN_ALPHA_GB if mode == "gaussian_blending" else MIN_ALPHA_3DGS
    keep &= opac >= min_alpha
    keep &= det > 0

    mid = 0.5 * (a + c)
    kr = GB_EXTENT if mode == "gaussian_blending" else 3.0
    lam_r = mid + np.sqrt(np.maximum(0.1, mid * mid - det))
    radius = np.ceil(kr * np.sqrt(np.maximum(lam_r, 0.0)))

    x, y = xy.T
    gx, gy = math.ceil(W / TILE), math.ceil(H / TILE)
    px, py = x - 0.5, y - 0.5
    with np.errstate(invalid="ignore"):
        x0 = np.clip((px - radius) / TILE, 0, gx).astype(np.int64)
        x1 = np.clip((px + radius + TILE - 1) / TILE, 0, gx).astype(np.int64)
        y0 = np.clip((py - radius) / TILE, 0, gy).astype(np.int64)
        y1 = np.clip((py + radius + TILE - 1) / TILE, 0, gy).astype(np.int64)
    keep &= (x1 > x0) & (y1 > y0)

    # eigen-decomposition of the (mode-adjusted) 2D covariance, robust angle form
    root = np.sqrt(np.maximum(0.0, mid * mid - det))
    lam1, lam2 = mid + root, mid - root
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    v1 = np.stack([np.cos(theta), np.sin(theta)], -1)
    v2 = np.stack([-np.sin(theta), np.cos(theta)], -1)

    vf = view_filter if mode == "scalar" and view_filter is not None else {}
    color = sh_to_rgb(sh, dirs, vf.get("dc_clamp", False))
    depth = np.linalg.norm(view, axis=1) if vf.get("sort_radial") and not cp["ortho"] else Z
    min_power = -0.5 * vf["support"] ** 2 if vf.get("support", 0.0) > 0 else -np.inf

    with np.errstate(divide="ignore", invalid="ignore"):
        conic = np.stack([c / det, -b / det, a / det], -1)
    return dict(
        keep=keep,
        xy=np.stack([x, y], -1),
        cov=np.stack([a, b, c], -1),
        conic=conic,
        opacity=opac,
        depth=depth,
        min_power=min_power,
        color=color,
        rect=np.stack([x0, x1, y0, y1], -1),
        radius=radius,
        lam=np.stack([lam1, lam2], -1),
        sigma=np.sqrt(np.abs(np.stack([lam1, lam2], -1))),
        v1=v1,
        v2=v2,
        W=W,
        H=H,
    )


def preprocess_cells(cells, cam, supersample: int = 1) -> dict:
    """Cells as Duplex-GS projects them (docs/modes.md#duplex): near cull, EWA +0.3, radius ceil(2 sqrt(lambda1))."""
    cp = camera_params(cam, supersample)
    W, H, R, t = (cp[k] for k in ("W", "H", "R", "t"))
    means = np.asarray(cells.means, np.float64)
    view = means @ R.T + t
    Z = view[:, 2]
    keep = Z > cp["near"]
    Rq = quat_to_rotmat(cells.quats)
    M = Rq * np.asarray(cells.scales, np.float64)[:, None, :]
    Sigma = M @ M.transpose(0, 2, 1)
    xy, cov = project(cp, view, Sigma, keep)
    a, b, c = cov[:, 0, 0] + 0.3, cov[:, 0, 1], cov[:, 1, 1] + 0.3
    det = a * c - b * b
    keep &= det > 0
    mid = 0.5 * (a + c)
    radius = np.ceil(2.0 * np.sqrt(mid + np.sqrt(np.maximum(0.1, mid * mid - det))))
    x, y = xy.T
    gx, gy = math.ceil(W / TILE), math.ceil(H / TILE)
    with np.errstate(invalid="ignore"):
        x0 = np.clip((x - 0.5 - radius) / TILE, 0, gx).astype(np.int64)
        x1 = np.clip((x - 0.5 + radius + TILE - 1) / TILE, 0, gx).astype(np.int64)
        y0 = np.clip((y - 0.5 - radius) / TILE, 0, gy).astype(np.int64)
        y1 = np.clip((y - 0.5 + radius + TILE - 1) / TILE, 0, gy).astype(np.int64)
    keep &= (x1 > x0) & (y1 > y0)
    return dict(keep=keep, depth=Z, rect=np.stack([x0, x1, y0, y1], -1))
