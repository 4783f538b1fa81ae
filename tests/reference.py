"""Brute-force float64 reference renderer, written from the written spec (KERNELS.md §0, §2, §4-§6,
gaussian-blending paper §3 and Appendix A-B; §7-§8 for wsr and duplex), independently of native/include/gbv/*.h.

It is deliberately simple: preprocess is vectorised over splats, blending loops over the depth-sorted
splats of each 16x16 tile and is vectorised over that tile's pixels (every pixel still runs its own
sequential front-to-back loop; vectorising over pixels does not change the per-pixel arithmetic).

Conventions (the ones gbviewer documents):
- pixel (i, j) covers [j, j+1] x [i, i+1], centre (j + 0.5, i + 0.5);
- screen position x = fx X/Z + cx, y = fy Y/Z + cy with (X, Y, Z) = R mean + t; for an orthographic camera
  x = fx X + cx, y = fy Y + cy, J = diag(fx, fy), and every SH view direction is the camera's forward axis;
- the tile rectangle is computed in the published integer-centre convention p = xy - 0.5.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf

from gbviewer.camera import NEAR_PLANE
from gbviewer.scene import SH_C0

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
DUPLEX_STOP = 0.01  # CUMMULT_THRESHOLD (KERNELS.md §8.1)
WSR_EMPTY = 1e-4
WSR_TERM_MAX = 64.0  # wsr: alpha and each colour term are capped here (the renderer's int64 fixed-point bound)

# Spherical-harmonics constants of 3DGS (KERNELS.md §0.5).
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


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
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def sh_to_rgb(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Evaluate the 3DGS real SH basis; sh (N,K,3), dirs (N,3) unit. Returns max(0, sum + 0.5)."""
    k = sh.shape[1]
    x, y, z = (dirs[:, i:i + 1] for i in range(3))
    res = SH_C0 * sh[:, 0]
    if k > 1:
        res = res - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        res = (res + SH_C2[0] * xy * sh[:, 4] + SH_C2[1] * yz * sh[:, 5]
               + SH_C2[2] * (2 * zz - xx - yy) * sh[:, 6] + SH_C2[3] * xz * sh[:, 7]
               + SH_C2[4] * (xx - yy) * sh[:, 8])
    if k > 9:
        res = (res + SH_C3[0] * y * (3 * xx - yy) * sh[:, 9] + SH_C3[1] * xy * z * sh[:, 10]
               + SH_C3[2] * y * (4 * zz - xx - yy) * sh[:, 11] + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
               + SH_C3[4] * x * (4 * zz - xx - yy) * sh[:, 13] + SH_C3[5] * z * (xx - yy) * sh[:, 14]
               + SH_C3[6] * x * (xx - 3 * yy) * sh[:, 15])
    return np.maximum(res + 0.5, 0.0)


def camera_params(cam, supersample: int = 1) -> dict:
    """Camera as float64, with the float32 rounding of R and t that the native call applies."""
    n = int(supersample)
    return dict(
        W=int(cam.width) * n, H=int(cam.height) * n,
        fx=float(np.float32(cam.fx)) * n, fy=float(np.float32(cam.fy)) * n,
        cx=float(np.float32(cam.cx)) * n, cy=float(np.float32(cam.cy)) * n,
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
        J[:, 0, 2] = -fx * tx / Zs ** 2
        J[:, 1, 1] = fy / Zs
        J[:, 1, 2] = -fy * ty / Zs ** 2
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
    """A 1-channel SH (N,K) at unit dirs (N,3): the raw sum (sort-free GS's v_i, KERNELS.md §7.3)."""
    k = c.shape[1]
    x, y, z = dirs.T
    res = SH_C0 * c[:, 0]
    if k > 1:
        res = res - SH_C1 * y * c[:, 1] + SH_C1 * z * c[:, 2] - SH_C1 * x * c[:, 3]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        res = (res + SH_C2[0] * xy * c[:, 4] + SH_C2[1] * yz * c[:, 5] + SH_C2[2] * (2 * zz - xx - yy) * c[:, 6]
               + SH_C2[3] * xz * c[:, 7] + SH_C2[4] * (xx - yy) * c[:, 8])
    if k > 9:
        res = (res + SH_C3[0] * y * (3 * xx - yy) * c[:, 9] + SH_C3[1] * xy * z * c[:, 10]
               + SH_C3[2] * y * (4 * zz - xx - yy) * c[:, 11] + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * c[:, 12]
               + SH_C3[4] * x * (4 * zz - xx - yy) * c[:, 13] + SH_C3[5] * z * (xx - yy) * c[:, 14]
               + SH_C3[6] * x * (xx - 3 * yy) * c[:, 15])
    return res


def preprocess(scene, cam, mode: str, supersample: int = 1, oit: dict | None = None) -> dict:
    """Per-splat screen-space quantities (float64). Arrays are indexed like the scene; `keep` marks survivors.

    wsr / duplex (KERNELS.md §7.2, §8.3): as scalar (+0.3, radius 3 sqrt(lambda_max)), and the opacity becomes
    o * v * (1 - z/sigma if depth_correct), with v the view-weight SH (raw) or 1; culled when z >= sigma
    (depth_correct) or v * correction <= 0."""
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
        s2 = scales ** 2
        opac = opac * np.sqrt(np.prod(s2, axis=1) / np.prod(s2 + f2[:, None], axis=1))
        scales = np.sqrt(s2 + f2[:, None])

    Rq = quat_to_rotmat(quats)
    M = Rq * scales[:, None, :]  # R S
    Sigma = M @ M.transpose(0, 2, 1)
    xy, cov = project(cp, view, Sigma, keep)
    dirs = view_dirs(cp, means)
    a, b, c = cov[:, 0, 0].copy(), cov[:, 0, 1].copy(), cov[:, 1, 1].copy()

    if mode in ("scalar",) + OIT_MODES:
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

    color = sh_to_rgb(sh, dirs)

    with np.errstate(divide="ignore", invalid="ignore"):
        conic = np.stack([c / det, -b / det, a / det], -1)
    return dict(
        keep=keep, xy=np.stack([x, y], -1), cov=np.stack([a, b, c], -1), conic=conic, opacity=opac,
        depth=Z, color=color, rect=np.stack([x0, x1, y0, y1], -1), radius=radius,
        lam=np.stack([lam1, lam2], -1), sigma=np.sqrt(np.abs(np.stack([lam1, lam2], -1))), v1=v1, v2=v2,
        W=W, H=H,
    )


def _phi_tilde(x):
    """Analytic-Splatting's CDF approximation sigmoid(1.6x + 0.07x^3)."""
    return 1.0 / (1.0 + np.exp(-(1.6 * x + 0.07 * x ** 3)))


def _g0(x):
    return math.sqrt(math.pi / 2) * erf(x / math.sqrt(2.0))


def _g1(x):
    return -np.expm1(-0.5 * x * x)


def _g2(x):
    return _g0(x) - x * np.exp(-0.5 * x * x)


# A threshold decision within this relative margin of its cut is a "tie" that float32 may decide the other
# way. Float32 alphas carry ~1e-7..1e-5 relative error (the analytic CDF differences of wide splats are the
# worst), transmittances ~1e-6 after a few hundred splats.
TIE_REL = 3e-5
# The early-stop test T (1 - alpha) < 1e-4 is reached behind nearly opaque splats, where a relative error e in
# alpha becomes e * alpha / (1 - alpha) in 1 - alpha; give it a wider margin.
TIE_REL_T = 2e-3


def _near(x, thr, rel=TIE_REL):
    return np.abs(x - thr) <= rel * abs(thr)


def _note(added, s, mask):
    """Append splat s to `added` (when given) if it added to some pixel of `mask`."""
    if added is not None and mask.any():
        added.append(int(s))


def _blend_scalar_like(pre, idx, pix, mode, added=None):
    """Scalar transmittance (scalar / mip / analytic). Returns C (P,3), T (P,), tie (P,) bool. `added`: a list that
    gets each splat some pixel adds (the blend loops of this module all take it; `pixel_contributors` uses it)."""
    P = pix.shape[0]
    C = np.zeros((P, 3))
    T = np.ones(P)
    done = np.zeros(P, bool)
    tie = np.zeros(P, bool)
    for s in idx:
        d = pix - pre["xy"][s]
        o = pre["opacity"][s]
        if mode == "analytic":
            sg1, sg2 = pre["sigma"][s]
            u = d @ pre["v1"][s]
            v = d @ pre["v2"][s]
            with np.errstate(over="ignore"):
                iu = sg1 * (_phi_tilde((u + 0.5) / sg1) - _phi_tilde((u - 0.5) / sg1))
                iv = sg2 * (_phi_tilde((v + 0.5) / sg2) - _phi_tilde((v - 0.5) / sg2))
            alpha = np.minimum(0.99, o * 2 * math.pi * iu * iv)
            ok = np.ones(P, bool)
        else:
            A, B, Cc = pre["conic"][s]
            power = -0.5 * (A * d[:, 0] ** 2 + Cc * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
            ok = power <= 0
            alpha = np.minimum(0.99, o * np.exp(np.minimum(power, 0.0)))
        tie |= ~done & _near(alpha, MIN_ALPHA_3DGS)
        ok &= ~done & (alpha >= MIN_ALPHA_3DGS)
        test_T = T * (1 - alpha)
        tie |= ok & _near(test_T, T_STOP, TIE_REL_T)
        stop = ok & (test_T < T_STOP)
        done |= stop
        add = ok & ~stop
        _note(added, s, add)
        C[add] += pre["color"][s] * (alpha[add] * T[add])[:, None]
        T = np.where(add, test_T, T)
    return C, T, tie


def _blend_gb(pre, idx, pix, state=None, return_centre=False, added=None):
    """Gaussian Blending transmittance window (KERNELS.md §6.3).

    Returns C (P,3), T (P,), window size (P,2), tie (P,) [, window centre (P,2)]. `state` = (T, centre, size)
    starts from a given window instead of (1, pixel centre, (1, 1)).
    """
    P = pix.shape[0]
    C = np.zeros((P, 3))
    Tv = np.ones(P)
    Txy = pix.copy()
    Twh = np.ones((P, 2))
    if state is not None:
        Tv, Txy, Twh = (np.array(np.broadcast_to(np.asarray(v, np.float64), sh))
                        for v, sh in zip(state, [(P,), (P, 2), (P, 2)]))
    done = np.zeros(P, bool)
    tie = np.zeros(P, bool)
    for s in idx:
        act = ~done
        if not act.any():
            break
        o = pre["opacity"][s]
        if o < MIN_ALPHA_GB:
            continue
        xy, v1, v2 = pre["xy"][s], pre["v1"][s], pre["v2"][s]
        sg1, sg2 = pre["sigma"][s]
        col = pre["color"][s]
        d = Txy - xy
        u, v = d @ v1, d @ v2
        # window sides go to the eigen-axis within 45 degrees of screen x ("max 45 degree rotation")
        swap = not (abs(v1[0]) > abs(v1[1]))
        w, h = (Twh[:, 1], Twh[:, 0]) if swap else (Twh[:, 0], Twh[:, 1])
        ru, rv = GB_EXTENT * sg1, GB_EXTENT * sg2
        outside = (u - w / 2 > ru) | (u + w / 2 < -ru) | (v - h / 2 > rv) | (v + h / 2 < -rv)
        # (no tie test here: a window touching the 3.33 sigma box has a mean alpha far below 1/256, so the
        # outside test changes nothing when it is decided either way)
        act = act & ~outside
        U1, U2 = (u - w / 2) / sg1, (u + w / 2) / sg1
        V1, V2 = (v - h / 2) / sg2, (v + h / 2) / sg2
        du, dv = U2 - U1, V2 - V1
        fb = (du < GB_MIN_UV) | (dv < GB_MIN_UV) | (du > GB_MAX_UV) | (dv > GB_MAX_UV)
        tie |= act & (_near(du, GB_MIN_UV) | _near(dv, GB_MIN_UV) | _near(du, GB_MAX_UV) | _near(dv, GB_MAX_UV))

        # fallback: scalar alpha at the window centre, window unchanged
        f = act & fb
        if f.any():
            A, B, Cc = pre["conic"][s]
            power = -0.5 * (A * d[:, 0] ** 2 + Cc * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
            alpha = np.minimum(0.99, o * np.exp(np.minimum(power, 0.0)))
            tie |= f & _near(alpha, MIN_ALPHA_GB)
            f &= (power <= 0) & (alpha >= MIN_ALPHA_GB)
            _note(added, s, f)
            wgt = Tv * alpha
            C[f] += col * wgt[f][:, None]
            Tv = np.where(f, Tv - wgt, Tv)
            tie |= f & _near(Tv, T_STOP, TIE_REL_T)
            done |= f & (Tv < T_STOP)

        # window path (eqs. 9-11 / Appendix A, with the published moment formulas)
        g = act & ~fb
        if g.any():
            I0u = sg1 * (_g0(U2) - _g0(U1))
            I0v = sg2 * (_g0(V2) - _g0(V1))
            area = w * h
            a = np.minimum(0.99, o * I0u * I0v / area)
            tie |= g & _near(a, MIN_ALPHA_GB)
            g &= a >= MIN_ALPHA_GB
            _note(added, s, g)
            wgt = Tv * a
            I1u = sg1 ** 2 * (_g1(U2) - _g1(U1))
            I1v = sg2 ** 2 * (_g1(V2) - _g1(V1))
            I2u = sg1 ** 3 * (_g2(U2) - _g2(U1))
            I2v = sg2 ** 3 * (_g2(V2) - _g2(V1))
            k = Tv / area * o
            m0 = Tv - wgt
            m1u = Tv * u - k * I1u * I0v
            m1v = Tv * v - k * I0u * I1v
            m2u = Tv * (u * u + w * w / 12) - k * I2u * I0v
            m2v = Tv * (v * v + h * h / 12) - k * I0u * I2v
            with np.errstate(divide="ignore", invalid="ignore"):
                mu, mv = m1u / m0, m1v / m0
                varu = np.maximum(m2u / m0 - mu * mu, GB_MIN_VAR)
                varv = np.maximum(m2v / m0 - mv * mv, GB_MIN_VAR)
            new_xy = xy + mu[:, None] * v1 + mv[:, None] * v2
            lu, lv = np.sqrt(12 * varu), np.sqrt(12 * varv)
            new_wh = np.stack([lv, lu], -1) if swap else np.stack([lu, lv], -1)
            C[g] += col * wgt[g][:, None]
            Tv = np.where(g, m0, Tv)
            Txy = np.where(g[:, None], new_xy, Txy)
            Twh = np.where(g[:, None], new_wh, Twh)
            tie |= g & _near(Tv, T_STOP, TIE_REL_T)
            done |= g & (Tv < T_STOP)
    if return_centre:
        return C, Tv, Twh, tie, Txy
    return C, Tv, Twh, tie


def _tile_lists(pre, mode: str, cam, supersample: int = 1, cells=None):
    """The tiles' lists: a function (tx, ty) -> splat indices in blend order, and (duplex) each splat's cell.

    Sorted modes: the kept splats whose rectangle touches the tile, by ascending depth (ties by index). wsr: the same
    splats in index order (the result does not depend on the order). duplex: cells with at least one kept splat,
    projected, sorted per tile by (depth, index), each expanded to its kept splats (in member order: the result
    depends on it only through rounding)."""
    kept = np.nonzero(pre["keep"])[0]

    def touching(ids, rect, tx, ty):
        return ids[(rect[:, 0] <= tx) & (tx < rect[:, 1]) & (rect[:, 2] <= ty) & (ty < rect[:, 3])]

    if mode == "duplex":
        cpre = preprocess_cells(cells, cam, supersample)
        members = [cells.members[cells.offsets[c]:cells.offsets[c + 1]] for c in range(len(cells.means))]
        members = [mm[pre["keep"][mm]] for mm in members]
        ckeep = cpre["keep"] & np.array([len(mm) > 0 for mm in members], bool)
        cell_of = np.full(len(pre["keep"]), -1)
        for c, mm in enumerate(members):
            cell_of[mm] = c
        corder = np.nonzero(ckeep)[0]
        corder = corder[np.argsort(cpre["depth"][corder], kind="stable")]
        crect = cpre["rect"][corder]

        def cell_list(tx, ty):
            cs = touching(corder, crect, tx, ty)
            return np.concatenate([members[c] for c in cs]) if len(cs) else np.zeros(0, int)

        return cell_list, cell_of
    order = kept if mode == "wsr" else kept[np.argsort(pre["depth"][kept], kind="stable")]
    rect = pre["rect"][order]
    return (lambda tx, ty: touching(order, rect, tx, ty)), None


def pixel_contributors(scene, cam, mode: str, x: int, y: int, supersample: int = 1, oit: dict | None = None,
                       cells=None) -> list[tuple[list[int], bool]]:
    """Per sub-sample of output pixel (x, y), row-major: the splats it adds, in blend order, and whether one of its
    threshold decisions was a tie; by this module's blend loops run on that sample alone."""
    n = int(supersample)
    pre = preprocess(scene, cam, mode, n, oit)
    lists, cell_of = _tile_lists(pre, mode, cam, n, cells)
    out = []
    for sy in range(n):
        for sx in range(n):
            hx, hy = x * n + sx, y * n + sy
            sel, pix, added, bg = lists(hx // TILE, hy // TILE), np.array([[hx + 0.5, hy + 0.5]]), [], np.zeros(3)
            if mode == "gaussian_blending":
                tie = _blend_gb(pre, sel, pix, added=added)[3]
            elif mode == "wsr":
                tie = _blend_wsr(pre, sel, pix, oit["weight_background"], bg, added)[2]
            elif mode == "duplex":
                tie = _blend_duplex(pre, sel, cell_of, pix, oit["et_grade"], oit["weight_background"], bg, added)[2]
            else:
                tie = _blend_scalar_like(pre, sel, pix, mode, added)[2]
            out.append((added, bool(tie[0])))
    return out


def render_full_res(scene, cam, mode: str, supersample: int = 1, background=(0.0, 0.0, 0.0)):
    """Render at the (super-sampled) resolution. Returns dict rgb (h,w,3), T (h,w), window (h,w,2),
    tie (h,w) bool, pre (the preprocess output)."""
    pre = preprocess(scene, cam, mode, supersample)
    W, H = pre["W"], pre["H"]
    gx, gy = math.ceil(W / TILE), math.ceil(H / TILE)
    bg = np.asarray(background, np.float64)
    rgb = np.zeros((H, W, 3))
    Tout = np.ones((H, W))
    win = np.ones((H, W, 2))
    ties = np.zeros((H, W), bool)
    lists, _ = _tile_lists(pre, mode, cam, supersample)
    for ty in range(gy):
        for tx in range(gx):
            sel = lists(tx, ty)
            i0, i1 = ty * TILE, min(H, (ty + 1) * TILE)
            j0, j1 = tx * TILE, min(W, (tx + 1) * TILE)
            ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1), indexing="ij")
            pix = np.stack([jj.ravel() + 0.5, ii.ravel() + 0.5], -1).astype(np.float64)
            if mode == "gaussian_blending":
                C, T, wh, tie = _blend_gb(pre, sel, pix)
                win[i0:i1, j0:j1] = wh.reshape(i1 - i0, j1 - j0, 2)
            else:
                C, T, tie = _blend_scalar_like(pre, sel, pix, mode)
            rgb[i0:i1, j0:j1] = (C + T[:, None] * bg).reshape(i1 - i0, j1 - j0, 3)
            Tout[i0:i1, j0:j1] = T.reshape(i1 - i0, j1 - j0)
            ties[i0:i1, j0:j1] = tie.reshape(i1 - i0, j1 - j0)
    return dict(rgb=rgb, T=Tout, window=win, tie=ties, pre=pre)


def preprocess_cells(cells, cam, supersample: int = 1) -> dict:
    """Cells as Duplex-GS projects them (KERNELS.md §8.3): near cull, EWA with +0.3, radius ceil(2 sqrt(lambda1))."""
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


def _blend_wsr(pre, idx, pix, wbg, bg, added=None):
    """LC-WSR (KERNELS.md §7.2) over the splats idx, in any order. Returns rgb (P,3), T' = wbg / total, tie."""
    P = pix.shape[0]
    C = np.zeros((P, 3))
    S = np.zeros(P)
    tie = np.zeros(P, bool)
    for s in idx:
        d = pix - pre["xy"][s]
        A, B, Cc = pre["conic"][s]
        power = -0.5 * (A * d[:, 0] ** 2 + Cc * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
        alpha = pre["opacity"][s] * np.exp(np.minimum(power, 0.0))
        tie |= _near(alpha, MIN_ALPHA_3DGS)
        ok = (power <= 0) & (alpha >= MIN_ALPHA_3DGS)
        _note(added, s, ok)
        alpha = np.minimum(alpha, WSR_TERM_MAX)
        C[ok] += np.minimum(pre["color"][s] * alpha[ok, None], WSR_TERM_MAX)
        S[ok] += alpha[ok]
    total = S + wbg
    total = np.where(total == 0, WSR_EMPTY, total)
    return (C + bg * wbg) / total[:, None], wbg / total, tie


def _blend_duplex(pre, idx, cell_of, pix, et, wbg, bg, added=None):
    """Duplex-GS (KERNELS.md §8.4) over a cell-sorted list idx. Returns rgb (P,3), T' = w_bg / total, tie."""
    P = pix.shape[0]
    C = np.zeros((P, 3))
    S = np.zeros(P)
    cum = np.ones(P)
    Tcell = np.ones(P)
    cur = np.full(P, -1)
    done = np.zeros(P, bool)
    tie = np.zeros(P, bool)
    for s in idx:
        d = pix - pre["xy"][s]
        r2 = pre["radius"][s] ** 2
        dd = d[:, 0] ** 2 + d[:, 1] ** 2
        A, B, Cc = pre["conic"][s]
        power = -0.5 * (A * d[:, 0] ** 2 + Cc * d[:, 1] ** 2) - B * d[:, 0] * d[:, 1]
        alpha = np.minimum(0.99, pre["opacity"][s] * np.exp(np.minimum(power, 0.0)))
        live = ~done & (power <= 0)
        tie |= live & (_near(alpha, MIN_ALPHA_3DGS) | (np.abs(dd - r2) <= TIE_REL * max(r2, 1.0)))
        ok = live & (dd <= r2) & (alpha >= MIN_ALPHA_3DGS)
        new = ok & (cur != cell_of[s])
        tie |= new & _near(cum, DUPLEX_STOP, TIE_REL_T)
        stop = new & (cum < DUPLEX_STOP)
        done |= stop
        ok &= ~stop
        _note(added, s, ok)
        enter = ok & new
        cur = np.where(enter, cell_of[s], cur)
        Tcell = np.where(enter, cum, Tcell)
        a = alpha / et
        w = np.where(ok, a * Tcell, 0.0)
        cum = np.where(ok, cum * (1.0 - a), cum)
        C += pre["color"][s] * w[:, None]
        S += w
    tie |= _near(cum, DUPLEX_STOP, TIE_REL_T)
    wb = np.where(cum < DUPLEX_STOP, 0.0, wbg)
    total = S + wb * cum
    total = np.where(total == 0, WSR_EMPTY, total)
    return (C + bg * wb[:, None]) / total[:, None], wb / total, tie


def render_oit(scene, cam, mode: str, oit: dict, cells=None, supersample: int = 1, background=(0.0, 0.0, 0.0)):
    """wsr / duplex at the (super-sampled) resolution (tile lists: `_tile_lists`); returns dict rgb, T (= w_bg /
    total, so alpha = 1 - T), tie."""
    pre = preprocess(scene, cam, mode, supersample, oit)
    W, H = pre["W"], pre["H"]
    gx, gy = math.ceil(W / TILE), math.ceil(H / TILE)
    bg = np.asarray(background, np.float64)
    rgb, Tout, ties = np.zeros((H, W, 3)), np.ones((H, W)), np.zeros((H, W), bool)
    lists, cell_of = _tile_lists(pre, mode, cam, supersample, cells)
    for ty in range(gy):
        for tx in range(gx):
            i0, i1 = ty * TILE, min(H, (ty + 1) * TILE)
            j0, j1 = tx * TILE, min(W, (tx + 1) * TILE)
            ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1), indexing="ij")
            pix = np.stack([jj.ravel() + 0.5, ii.ravel() + 0.5], -1).astype(np.float64)
            sel = lists(tx, ty)
            if mode == "wsr":
                out, T, tie = _blend_wsr(pre, sel, pix, oit["weight_background"], bg)
            else:
                out, T, tie = _blend_duplex(pre, sel, cell_of, pix, oit["et_grade"], oit["weight_background"], bg)
            rgb[i0:i1, j0:j1] = out.reshape(i1 - i0, j1 - j0, 3)
            Tout[i0:i1, j0:j1] = T.reshape(i1 - i0, j1 - j0)
            ties[i0:i1, j0:j1] = tie.reshape(i1 - i0, j1 - j0)
    return dict(rgb=rgb, T=Tout, tie=ties, pre=pre)


def reference_render_oit(scene, cam, mode: str, oit: dict, cells=None, supersample: int = 1,
                         background=(0.0, 0.0, 0.0)):
    """(rgb, alpha = 1 - w_bg / total, tie mask) at output resolution, box-averaged like the renderer."""
    n = int(supersample)
    r = render_oit(scene, cam, mode, oit, cells, n, background)
    return box_down(r["rgb"], n), box_down(1.0 - r["T"], n), box_down(r["tie"].astype(float), n) > 0


def box_down(img: np.ndarray, n: int) -> np.ndarray:
    """Average n x n blocks of the first two axes."""
    if n == 1:
        return img
    h, w = img.shape[0] // n, img.shape[1] // n
    return img.reshape(h, n, w, n, *img.shape[2:]).mean(axis=(1, 3))


def reference_render(scene, cam, mode: str, supersample: int = 1, background=(0.0, 0.0, 0.0),
                     return_window: bool = False, return_ties: bool = False):
    """Float64 brute-force render. Returns (rgb (H,W,3), alpha (H,W)), then optionally the final GB window
    size (H,W,2) (None unless supersample == 1) and the tie mask (H,W): output pixels where some
    threshold decision (alpha cut, early stop, GB fallback / extent test) lay within TIE_REL of its cut.
    """
    n = int(supersample)
    r = render_full_res(scene, cam, mode, n, background)
    out = (box_down(r["rgb"], n), box_down(1.0 - r["T"], n))
    if return_window:
        out = out + (r["window"] if n == 1 else None,)
    if return_ties:
        out = out + (box_down(r["tie"].astype(float), n) > 0,)
    return out
