"""Rigid, similarity and affine transforms of splats: centres, covariances and the SH colour's view dependence.

A 4x4 matrix M = [A t] moves a centre to A p + t and a covariance to A S A^T; a similarity A = c Q (Q orthogonal)
keeps the splat's axes (rotation Q's proper part times the splat's, scales times c), any other A gives the axes
and scales of A S A^T by eigendecomposition. The SH colour f(d) becomes f(Q^T d) with Q the orthogonal factor of
A (its polar decomposition): each band's coefficients mix by the matrix that rotates that band, found by fitting
the band's basis at fixed directions (exact: a band is closed under rotations and reflections).
"""

from __future__ import annotations

import numpy as np

from ..model.cells import quats_from_matrices, rotation_matrices
from ..model.scene import SH_C0

SIMILAR = 1e-6  # relative spread of A's singular values below which A is treated as a similarity
_BANDS = {1: slice(1, 4), 2: slice(4, 9), 3: slice(9, 16)}


def sh_basis(dirs: np.ndarray, k: int) -> np.ndarray:
    """The 3DGS real SH basis (graphdeco-inria/gaussian-splatting utils/sh_utils.py, the same constants as
    KHR_gaussian_splatting's appendix) of the first `k` coefficients at unit directions (A,3): (A,k) float64."""
    x, y, z = np.asarray(dirs, np.float64).T
    basis = [np.full_like(x, SH_C0)]
    if k > 1:
        c1 = 0.4886025119029199
        basis += [-c1 * y, c1 * z, -c1 * x]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        basis += [
            1.0925484305920792 * xy,
            -1.0925484305920792 * yz,
            0.31539156525252005 * (2 * zz - xx - yy),
            -1.0925484305920792 * xz,
            0.5462742152960396 * (xx - yy),
        ]
    if k > 9:
        basis += [
            -0.5900435899266435 * y * (3 * xx - yy),
            2.890611442640554 * xy * z,
            -0.4570457994644658 * y * (4 * zz - xx - yy),
            0.3731763325901154 * z * (2 * zz - 3 * xx - 3 * yy),
            -0.4570457994644658 * x * (4 * zz - xx - yy),
            1.445305721320277 * z * (xx - yy),
            -0.5900435899266435 * x * (xx - 3 * yy),
        ]
    return np.stack(basis[:k], 1)


def rotate_sh(sh: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N,K,3) SH coefficients of f, as those of d -> f(Q^T d) for an orthogonal (3,3) `q`."""
    k = sh.shape[1]
    if k == 1:
        return sh
    dirs = np.random.default_rng(0).normal(size=(64, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    before, after = sh_basis(dirs, k), sh_basis(dirs @ q, k)  # row i of dirs @ q is Q^T d_i
    out = np.array(sh, np.float64)
    for band in (b for b in _BANDS.values() if b.stop <= k):
        mix = np.linalg.lstsq(before[:, band], after[:, band], rcond=None)[0]  # basis(Q^T d) = basis(d) @ mix
        out[:, band] = np.einsum("ij,njc->nic", mix, out[:, band])
    return out.astype(sh.dtype)


def apply_matrix(
    m: np.ndarray, means: np.ndarray, scales: np.ndarray, quats: np.ndarray, sh: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Splats (quats (w,x,y,z)) moved by the 4x4 matrix `m`, in float64, returned as float32."""
    a, t = np.asarray(m, np.float64)[:3, :3], np.asarray(m, np.float64)[:3, 3]
    u, sing, vt = np.linalg.svd(a)
    q = u @ vt
    new_means = (means.astype(np.float64) @ a.T + t).astype(np.float32)
    if sing.max() - sing.min() <= SIMILAR * sing.max():
        proper = q * np.sign(np.linalg.det(q))  # -I commutes with every covariance: drop a reflection
        rot = quats_from_matrices(proper[None])[0]
        new_quats = _multiply(rot, quats.astype(np.float64))
        new_scales = scales.astype(np.float64) * sing.mean()
    else:
        r = rotation_matrices(quats)
        cov = np.einsum("ij,njk,nk,nlk,ml->nim", a, r, scales.astype(np.float64) ** 2, r, a)
        vals, vecs = np.linalg.eigh(cov)
        vecs[np.linalg.det(vecs) < 0, :, 0] *= -1  # a proper rotation: eigenvectors' signs are free
        new_quats, new_scales = quats_from_matrices(vecs), np.sqrt(np.maximum(vals, 0.0))
    return new_means, new_scales.astype(np.float32), new_quats.astype(np.float32), rotate_sh(sh, q)


def _multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The Hamilton product p q of one quaternion `p` and (N,4) `q`, all (w,x,y,z)."""
    w0, x0, y0, z0 = p
    w, x, y, z = q.T
    return np.stack(
        [
            w0 * w - x0 * x - y0 * y - z0 * z,
            w0 * x + x0 * w + y0 * z - z0 * y,
            w0 * y - x0 * z + y0 * w + z0 * x,
            w0 * z + x0 * y - y0 * x + z0 * w,
        ],
        1,
    )
