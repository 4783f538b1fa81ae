"""Brute-force float64 reference renderer, written from the written spec (docs/modes.md,
the Gaussian Blending paper's §3 and Appendix A-B), independently of native/include/gbv/*.h.

It is deliberately simple: preprocess is vectorised over splats, blending loops over the depth-sorted
splats of each 16x16 tile and is vectorised over that tile's pixels (every pixel still runs its own
sequential front-to-back loop; vectorising over pixels does not change the per-pixel arithmetic).
This module holds the tile lists and the renders; `reference_preprocess` the preprocess, `reference_blend` the
blend loops.

Conventions (the ones gbviewer documents):
- pixel (i, j) covers [j, j+1] x [i, i+1], centre (j + 0.5, i + 0.5);
- screen position x = fx X/Z + cx, y = fy Y/Z + cy with (X, Y, Z) = R mean + t; for an orthographic camera
  x = fx X + cx, y = fy Y + cy, J = diag(fx, fy), and every SH view direction is the camera's forward axis;
- the tile rectangle is computed in the published integer-centre convention p = xy - 0.5.
"""

from __future__ import annotations

import math

import numpy as np
from reference_blend import blend_duplex, blend_gb, blend_scalar_like, blend_wsr
from reference_preprocess import MODES, TILE, preprocess, preprocess_cells

__all__ = ["MODES", "pixel_contributors", "reference_render", "reference_render_oit"]  # what the tests use


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
        members = [cells.members[cells.offsets[c] : cells.offsets[c + 1]] for c in range(len(cells.means))]
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


def pixel_contributors(
    scene, cam, mode: str, x: int, y: int, supersample: int = 1, oit: dict | None = None, cells=None
) -> list[tuple[list[int], bool]]:
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
                tie = blend_gb(pre, sel, pix, added=added)[3]
            elif mode == "wsr":
                tie = blend_wsr(pre, sel, pix, oit["weight_background"], bg, added)[2]
            elif mode == "duplex":
                tie = blend_duplex(pre, sel, cell_of, pix, oit["et_grade"], oit["weight_background"], bg, added)[2]
            else:
                tie = blend_scalar_like(pre, sel, pix, mode, added)[2]
            out.append((added, bool(tie[0])))
    return out


def render_full_res(scene, cam, mode: str, supersample: int = 1, background=(0.0, 0.0, 0.0), view_filter=None):
    """Render at the (super-sampled) resolution. Returns dict rgb (h,w,3), T (h,w), window (h,w,2),
    tie (h,w) bool, pre (the preprocess output)."""
    pre = preprocess(scene, cam, mode, supersample, view_filter=view_filter)
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
                C, T, wh, tie = blend_gb(pre, sel, pix)
                win[i0:i1, j0:j1] = wh.reshape(i1 - i0, j1 - j0, 2)
            else:
                C, T, tie = blend_scalar_like(pre, sel, pix, mode)
            rgb[i0:i1, j0:j1] = (C + T[:, None] * bg).reshape(i1 - i0, j1 - j0, 3)
            Tout[i0:i1, j0:j1] = T.reshape(i1 - i0, j1 - j0)
            ties[i0:i1, j0:j1] = tie.reshape(i1 - i0, j1 - j0)
    return dict(rgb=rgb, T=Tout, window=win, tie=ties, pre=pre)


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
                out, T, tie = blend_wsr(pre, sel, pix, oit["weight_background"], bg)
            else:
                out, T, tie = blend_duplex(pre, sel, cell_of, pix, oit["et_grade"], oit["weight_background"], bg)
            rgb[i0:i1, j0:j1] = out.reshape(i1 - i0, j1 - j0, 3)
            Tout[i0:i1, j0:j1] = T.reshape(i1 - i0, j1 - j0)
            ties[i0:i1, j0:j1] = tie.reshape(i1 - i0, j1 - j0)
    return dict(rgb=rgb, T=Tout, tie=ties, pre=pre)


def reference_render_oit(
    scene, cam, mode: str, oit: dict, cells=None, supersample: int = 1, background=(0.0, 0.0, 0.0)
):
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


def reference_render(
    scene,
    cam,
    mode: str,
    supersample: int = 1,
    background=(0.0, 0.0, 0.0),
    return_window: bool = False,
    return_ties: bool = False,
    view_filter: dict | None = None,
):
    """Float64 brute-force render. Returns (rgb (H,W,3), alpha (H,W)), then optionally the final GB window
    size (H,W,2) (None unless supersample == 1) and the tie mask (H,W): output pixels where some
    threshold decision (alpha cut, early stop, GB fallback / extent test) lay within TIE_REL of its cut.
    """
    n = int(supersample)
    r = render_full_res(scene, cam, mode, n, background, view_filter)
    out = (box_down(r["rgb"], n), box_down(1.0 - r["T"], n))
    if return_window:
        out = out + (r["window"] if n == 1 else None,)
    if return_ties:
        out = out + (box_down(r["tie"].astype(float), n) > 0,)
    return out
