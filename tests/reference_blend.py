"""The reference renderer's blend loops (see reference.py): scalar-like modes, Gaussian Blending's window, wsr
and duplex, each over one tile's pixels, with the threshold ties float32 may decide the other way."""

from __future__ import annotations

import math

import numpy as np
from reference_preprocess import (
    DUPLEX_STOP,
    GB_EXTENT,
    GB_MAX_UV,
    GB_MIN_UV,
    GB_MIN_VAR,
    MIN_ALPHA_3DGS,
    MIN_ALPHA_GB,
    T_STOP,
    WSR_EMPTY,
    WSR_TERM_MAX,
)
from scipy.special import erf


def _phi_tilde(x):
    """Analytic-Splatting's CDF approximation sigmoid(1.6x + 0.07x^3)."""
    return 1.0 / (1.0 + np.exp(-(1.6 * x + 0.07 * x**3)))


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


def blend_scalar_like(pre, idx, pix, mode, added=None):
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
            ok = (power <= 0) & (power >= pre.get("min_power", -np.inf))  # a preset's support cut
            if np.isfinite(pre.get("min_power", -np.inf)):
                tie |= ~done & _near(power, pre["min_power"])
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


def blend_gb(pre, idx, pix, state=None, return_centre=False, added=None):
    """Gaussian Blending transmittance window (docs/modes.md#gaussian-blending).

    Returns C (P,3), T (P,), window size (P,2), tie (P,) [, window centre (P,2)]. `state` = (T, centre, size)
    starts from a given window instead of (1, pixel centre, (1, 1)).
    """
    P = pix.shape[0]
    C = np.zeros((P, 3))
    Tv = np.ones(P)
    Txy = pix.copy()
    Twh = np.ones((P, 2))
    if state is not None:
        Tv, Txy, Twh = (
            np.array(np.broadcast_to(np.asarray(v, np.float64), sh)) for v, sh in zip(state, [(P,), (P, 2), (P, 2)])
        )
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
            I1u = sg1**2 * (_g1(U2) - _g1(U1))
            I1v = sg2**2 * (_g1(V2) - _g1(V1))
            I2u = sg1**3 * (_g2(U2) - _g2(U1))
            I2v = sg2**3 * (_g2(V2) - _g2(V1))
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


def blend_wsr(pre, idx, pix, wbg, bg, added=None):
    """LC-WSR (docs/modes.md#wsr) over the splats idx, in any order. Returns rgb (P,3), T' = wbg / total, tie."""
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


def blend_duplex(pre, idx, cell_of, pix, et, wbg, bg, added=None):
    """Duplex-GS (docs/modes.md#duplex) over a cell-sorted list idx. Returns rgb (P,3), T' = w_bg / total, tie."""
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
