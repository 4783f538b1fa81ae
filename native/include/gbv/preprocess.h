// Per-splat preprocess: cull, covariance, EWA projection, per-mode 2D filter, eigen-decomposition,
// colour from SH, tile rectangle. One function for every backend (KERNELS.md §0, §2, §4, §6.2).
#pragma once

#include "common.h"
#include "lanes.h"

namespace gbv {

constexpr float SH_C0 = 0.28209479177387814f;
constexpr float SH_C1 = 0.4886025119029199f;
// Scalars rather than arrays: nvcc cannot read namespace-scope constexpr arrays in device code.
constexpr float SH_C2_0 = 1.0925484305920792f, SH_C2_1 = -1.0925484305920792f, SH_C2_2 = 0.31539156525252005f,
                SH_C2_3 = -1.0925484305920792f, SH_C2_4 = 0.5462742152960396f;
constexpr float SH_C3_0 = -0.5900435899266435f, SH_C3_1 = 2.890611442640554f, SH_C3_2 = -0.4570457994644658f,
                SH_C3_3 = 0.3731763325901154f, SH_C3_4 = -0.4570457994644658f, SH_C3_5 = 1.445305721320277f,
                SH_C3_6 = -0.5900435899266435f;

// Every step is written once, as a template over a lane type L (lanes.h) like blend.h's: L::F holds one float per
// splat lane, L::M one flag per lane, so the same source compiles to the one-splat functions (Lanes1: CUDA, the GLSL
// port's reference and the scalar CPU path) and to the CPU's vector preprocess (native/cpu/preprocess_isa.cpp, 8 or
// 16 splats at once). Culling is a lane mask; a lane culled early computes on and is dropped at the end, and the work
// stops when no lane is left. Every lane type computes the same IEEE operations in the same order (its mul_rn,
// fmin/fmax, frexp and ceil are libm's, bit for bit), so the vector preprocess is bit-identical to the scalar one.
// The one-splat wrappers keep the signatures CUDA and the GLSL port use.

// Real SH basis of degree `deg` (0..3) at the unit direction `dir`, in the 3DGS order and signs; returns the
// number of coefficients used, (deg + 1)^2.
template <class L>
GBV_HD int sh_basis(int deg, const typename L::F dir[3], typename L::F basis[16]) {
    using F = typename L::F;
    const F x = dir[0], y = dir[1], z = dir[2];
    basis[0] = L::set(SH_C0);
    if (deg < 1) return 1;
    basis[1] = L::set(-SH_C1) * y;
    basis[2] = L::set(SH_C1) * z;
    basis[3] = L::set(-SH_C1) * x;
    if (deg < 2) return 4;
    const F xx = L::mul_rn(x, x), yy = L::mul_rn(y, y), zz = L::mul_rn(z, z), xy = x * y, yz = y * z, xz = x * z;
    const F two = L::set(2.0f), three = L::set(3.0f), four = L::set(4.0f);
    basis[4] = L::set(SH_C2_0) * xy;
    basis[5] = L::set(SH_C2_1) * yz;
    basis[6] = L::set(SH_C2_2) * (L::mul_rn(two, zz) - xx - yy);
    basis[7] = L::set(SH_C2_3) * xz;
    basis[8] = L::set(SH_C2_4) * (xx - yy);
    if (deg < 3) return 9;
    basis[9] = L::set(SH_C3_0) * y * (L::mul_rn(three, xx) - yy);
    basis[10] = L::set(SH_C3_1) * xy * z;
    basis[11] = L::set(SH_C3_2) * y * (L::mul_rn(four, zz) - xx - yy);
    basis[12] = L::set(SH_C3_3) * z * (L::mul_rn(two, zz) - L::mul_rn(three, xx) - L::mul_rn(three, yy));
    basis[13] = L::set(SH_C3_4) * x * (L::mul_rn(four, zz) - xx - yy);
    basis[14] = L::set(SH_C3_5) * z * (xx - yy);
    basis[15] = L::set(SH_C3_6) * x * (xx - L::mul_rn(three, yy));
    return 16;
}

// View-dependent colour from SH coefficients sh[K][3] (DC first), as computeColorFromSH:
// +0.5 offset, clamped at 0 from below only.
template <class L>
GBV_HD void sh_to_rgb(const typename L::F* sh, int deg, const typename L::F dir[3], typename L::F out[3]) {
    typename L::F basis[16];
    const int k = sh_basis<L>(deg, dir, basis);
    for (int c = 0; c < 3; ++c) {
        typename L::F v = L::set(0.5f);
        for (int i = 0; i < k; ++i) v = v + L::mul_rn(basis[i], sh[i * 3 + c]);
        out[c] = L::fmax(v, L::set(0.0f));
    }
}

// Sort-free GS's view-dependent weight v_i (KERNELS.md §7.3): a 1-channel SH w[K] (f_do_0, f_ro_*), the raw
// sum: no +0.5, no clamp (non-positive weights are culled by the caller).
template <class L>
GBV_HD typename L::F sh_to_weight(const typename L::F* w, int deg, const typename L::F dir[3]) {
    typename L::F basis[16];
    const int k = sh_basis<L>(deg, dir, basis);
    typename L::F v = L::set(0.0f);
    for (int i = 0; i < k; ++i) v = v + L::mul_rn(basis[i], w[i]);
    return v;
}

// 3D covariance Sigma = R S S^T R^T (upper triangle: xx, xy, xz, yy, yz, zz) from a unit (w,x,y,z)
// quaternion and per-axis scales (eq. 1).
template <class L>
GBV_HD void covariance_3d(const typename L::F q[4], const typename L::F s[3], typename L::F cov[6]) {
    using F = typename L::F;
    const F r = q[0], x = q[1], y = q[2], z = q[3];
    const F xx = L::mul_rn(x, x), yy = L::mul_rn(y, y), zz = L::mul_rn(z, z), xy = L::mul_rn(x, y),
            xz = L::mul_rn(x, z), yz = L::mul_rn(y, z), rx = L::mul_rn(r, x), ry = L::mul_rn(r, y),
            rz = L::mul_rn(r, z);
    const F one = L::set(1.0f), two = L::set(2.0f);
    const F R[9] = {one - L::mul_rn(two, yy + zz), two * (xy - rz),                two * (xz + ry),
                    two * (xy + rz),                one - L::mul_rn(two, xx + zz), two * (yz - rx),
                    two * (xz - ry),                two * (yz + rx),                one - L::mul_rn(two, xx + yy)};
    F M[9];  // M = R S
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) M[i * 3 + j] = R[i * 3 + j] * s[j];
    cov[0] = L::mul_rn(M[0], M[0]) + L::mul_rn(M[1], M[1]) + L::mul_rn(M[2], M[2]);
    cov[1] = L::mul_rn(M[0], M[3]) + L::mul_rn(M[1], M[4]) + L::mul_rn(M[2], M[5]);
    cov[2] = L::mul_rn(M[0], M[6]) + L::mul_rn(M[1], M[7]) + L::mul_rn(M[2], M[8]);
    cov[3] = L::mul_rn(M[3], M[3]) + L::mul_rn(M[4], M[4]) + L::mul_rn(M[5], M[5]);
    cov[4] = L::mul_rn(M[3], M[6]) + L::mul_rn(M[4], M[7]) + L::mul_rn(M[5], M[8]);
    cov[5] = L::mul_rn(M[6], M[6]) + L::mul_rn(M[7], M[7]) + L::mul_rn(M[8], M[8]);
}

// EWA projection of a 3D covariance to screen space (eq. 3): J W Sigma W^T J^T, with the view-space
// point clamped to 1.3x the frustum for the Jacobian only (computeCov2D). An orthographic camera's projection is
// linear: J = diag(fx, fy) (no depth terms, nothing to clamp). Returns (a, b, c).
template <class L>
GBV_HD void project_covariance(const CameraParams& cam, const typename L::F cov3[6], const typename L::F pv[3],
                               typename L::F out[3]) {
    using F = typename L::F;
    F j00 = L::set(cam.fx), j02 = L::set(0.0f), j11 = L::set(cam.fy), j12 = L::set(0.0f);
    if (cam.projection != ORTHOGRAPHIC) {
        const F tz = pv[2];
        // clampf(v, lo, hi) = fminf(fmaxf(v, lo), hi)
        const F tx = L::fmin(L::fmax(pv[0] / tz, L::set(-cam.lim_x_neg)), L::set(cam.lim_x_pos)) * tz;
        const F ty = L::fmin(L::fmax(pv[1] / tz, L::set(-cam.lim_y_neg)), L::set(cam.lim_y_pos)) * tz;
        j00 = L::set(cam.fx) / tz;
        j02 = L::set(-cam.fx) * tx / (tz * tz);
        j11 = L::set(cam.fy) / tz;
        j12 = L::set(-cam.fy) * ty / (tz * tz);
    }
    const float* W = cam.R;
    // T = J W (2x3)
    F T[6];
    for (int c = 0; c < 3; ++c) {
        T[c] = L::mul_rn(j00, L::set(W[c])) + L::mul_rn(j02, L::set(W[6 + c]));
        T[3 + c] = L::mul_rn(j11, L::set(W[3 + c])) + L::mul_rn(j12, L::set(W[6 + c]));
    }
    const F S[9] = {cov3[0], cov3[1], cov3[2], cov3[1], cov3[3], cov3[4], cov3[2], cov3[4], cov3[5]};
    F TS[6];
    for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c)
            TS[r * 3 + c] = L::mul_rn(T[r * 3], S[c]) + L::mul_rn(T[r * 3 + 1], S[3 + c]) +
                            L::mul_rn(T[r * 3 + 2], S[6 + c]);
    out[0] = L::mul_rn(TS[0], T[0]) + L::mul_rn(TS[1], T[1]) + L::mul_rn(TS[2], T[2]);
    out[1] = L::mul_rn(TS[0], T[3]) + L::mul_rn(TS[1], T[4]) + L::mul_rn(TS[2], T[5]);
    out[2] = L::mul_rn(TS[3], T[3]) + L::mul_rn(TS[4], T[4]) + L::mul_rn(TS[5], T[5]);
}

// Eigen-decomposition of a 2x2 covariance (a, b, c): sigma = sqrt(eigenvalues) and the unit major
// eigenvector. lambda2 = det / lambda1 equals mid - sqrt(mid^2 - det) exactly and avoids cancellation;
// the eigenvector is taken from whichever of its two formulas is better conditioned, so isotropic
// splats get a valid axis instead of normalize(0, 0).
template <class L>
GBV_HD void eigen_2d(typename L::F a, typename L::F b, typename L::F c, typename L::F det, typename L::F* sigma1,
                     typename L::F* sigma2, typename L::F v1[2]) {
    using F = typename L::F;
    const F mid = L::set(0.5f) * (a + c);
    const F root = L::sqrt(L::fmax(L::set(0.0f), mid * mid - det));
    const F l1 = mid + root;
    const F l2 = det / l1;
    *sigma1 = L::sqrt(l1);
    *sigma2 = L::sqrt(l2);
    const F e1x = b, e1y = l1 - a, e2x = l1 - c, e2y = b;
    const F n1 = e1x * e1x + e1y * e1y, n2 = e2x * e2x + e2y * e2y;  // dot(e, e)
    const typename L::M first = n1 >= n2;
    const F ex = L::select(first, e1x, e2x), ey = L::select(first, e1y, e2y);
    const F n = L::fmax(n1, n2);
    const typename L::M ok = n > L::set(1e-30f);
    const F k = L::set(1.0f) / L::sqrt(n);
    v1[0] = L::select(ok, k * ex, L::set(1.0f));
    v1[1] = L::select(ok, k * ey, L::set(0.0f));
}

// Screen-space bounding radius in pixels: ceil(k * sqrt(max eigenvalue)) with the published
// max(0.1, mid^2 - det) floor.
template <class L>
GBV_HD typename L::F splat_radius(typename L::F a, typename L::F c, typename L::F det, float sigmas) {
    using F = typename L::F;
    const F mid = L::mul_rn(L::set(0.5f), a + c);
    const F lmax = mid + L::sqrt(L::fmax(L::set(0.1f), L::mul_rn(mid, mid) - det));
    return L::ceil(L::set(sigmas) * L::sqrt(lmax));
}

// ln(x) for x >= 1, from above, by basic float operations only, so that every backend computes the same value (logf
// differs in its last bit between libm, CUDA and GLSL): x = m 2^e with m in [1, 2) (exact), ln m <= t - t^2/2 + t^3/3
// with t = m - 1 (the alternating series cut after a positive term; at most 0.14 above).
template <class L>
GBV_HD typename L::F log_upper(typename L::F x) {
    using F = typename L::F;
    typename L::I e;
    const F m = L::set(2.0f) * L::frexp(x, &e);  // x = m 2^(e - 1)
    const F t = m - L::set(1.0f), t2 = L::mul_rn(t, t);
    return L::mul_rn(L::to_float(e - L::seti(1)), L::set(0.69314720f)) + t - L::mul_rn(L::set(0.5f), t2) +
           L::mul_rn(L::mul_rn(t2, t), L::set(0.33333334f));
}

// Half sides (x, y) of the screen box that binning gives a splat. scalar, mip, wsr and duplex skip a pixel where
// power < ln(min_alpha / opacity), i.e. outside the ellipse d^T Sigma^-1 d <= r2 = 2 ln(opacity / min_alpha), whose
// bounding box has half sides sqrt(r2 Sigma_xx) and sqrt(r2 Sigma_yy): widened for the blend's float rounding
// (relative 1e-5 + 1e-6 lambda1^2 / det, plus 0.02 px), rounded up to whole pixels, plus one pixel (getRect's upper
// edge takes a tile only when the box reaches 1 px into it: tight to the pixel, it would drop the tile's first row or
// column), and capped by the radius r (the published square): no tile a pixel could take the splat in is dropped.
// gaussian_blending (its windows move: the published 3.33 sigma square) and analytic (alpha integrated over the
// pixel): the radius.
template <class L>
GBV_HD void cutoff_half_sides(Mode mode, const typename L::F cov[3], typename L::F det, typename L::F opacity,
                              float min_alpha, typename L::F r, typename L::F h[2]) {
    using F = typename L::F;
    if (mode == GAUSSIAN_BLENDING || mode == ANALYTIC) {
        h[0] = h[1] = r;
        return;
    }
    // + 1e-6: the blend's threshold is logf(min_alpha / opacity), from the other quotient (up to ~2e-7 apart)
    const F r2 = L::mul_rn(L::set(2.0f), log_upper<L>(opacity / L::set(min_alpha))) + L::set(1e-6f);
    const F mid = L::mul_rn(L::set(0.5f), cov[0] + cov[2]);
    const F l1 = mid + L::sqrt(L::fmax(L::set(0.0f), L::mul_rn(mid, mid) - det));
    const F grow = L::set(1.00001f) + L::mul_rn(L::set(1e-6f), L::mul_rn(l1, l1) / det);
    const F hx = L::ceil(L::mul_rn(L::sqrt(r2 * cov[0]), grow) + L::set(0.02f)) + L::set(1.0f);
    const F hy = L::ceil(L::mul_rn(L::sqrt(r2 * cov[2]), grow) + L::set(0.02f)) + L::set(1.0f);
    h[0] = L::min(hx, r);  // minf: a NaN side becomes r
    h[1] = L::min(hy, r);
}

// Tile rectangles [x0, x1) x [y0, y1) of L::N splats, one per lane.
template <class L>
struct TileRectLanes {
    typename L::I x0, y0, x1, y1;
};

// Tiles touched by a splat at xy with half sides h (getRect, which has h = (r, r)), in the published integer-centre
// pixel convention (our xy minus 0.5). Empty when x1 <= x0 or y1 <= y0.
template <class L>
GBV_HD TileRectLanes<L> tile_rect(const typename L::F xy[2], const typename L::F h[2], int grid_x, int grid_y) {
    using F = typename L::F;
    const F px = xy[0] - L::set(0.5f), py = xy[1] - L::set(0.5f);
    const F zero = L::set(0.0f), gx = L::set((float)grid_x), gy = L::set((float)grid_y), tile = L::set((float)TILE);
    const F edge = L::set((float)TILE), one = L::set(1.0f);
    TileRectLanes<L> t;  // (int)clampf(v, 0, g): truncation of a value in [0, g]
    t.x0 = L::to_int(L::fmin(L::fmax((px - h[0]) / tile, zero), gx));
    t.y0 = L::to_int(L::fmin(L::fmax((py - h[1]) / tile, zero), gy));
    t.x1 = L::to_int(L::fmin(L::fmax((px + h[0] + edge - one) / tile, zero), gx));
    t.y1 = L::to_int(L::fmin(L::fmax((py + h[1] + edge - one) / tile, zero), gy));
    return t;
}

GBV_HD TileRect tile_rect(Vec2 xy, Vec2 h, int grid_x, int grid_y) {
    const float p[2] = {xy.x, xy.y}, hh[2] = {h.x, h.y};
    const TileRectLanes<Lanes1> t = tile_rect<Lanes1>(p, hh, grid_x, grid_y);
    return TileRect{t.x0, t.y0, t.x1, t.y1};
}

// Tiles of rectangle q outside rectangle r: duplex's cell_misses statistic counts a splat's tiles outside its cell's.
GBV_HD int64_t tiles_outside(const TileRect& q, const TileRect& r) {
    const int ix = (q.x1 < r.x1 ? q.x1 : r.x1) - (q.x0 > r.x0 ? q.x0 : r.x0);
    const int iy = (q.y1 < r.y1 ? q.y1 : r.y1) - (q.y0 > r.y0 ? q.y0 : r.y0);
    return (int64_t)(q.x1 - q.x0) * (q.y1 - q.y0) - (ix > 0 && iy > 0 ? (int64_t)ix * iy : 0);
}

// Inputs of one splat (activated parameters, see gbviewer.Scene).
struct SplatIn {
    const float* mean;   // 3
    const float* scale;  // 3
    const float* quat;   // 4 (w, x, y, z), unit
    float opacity;
    const float* sh;     // K*3
    float filter_3d;     // 0 when the scene has none
    const float* weight_sh;  // sort-free view weight, weight_deg's (deg+1)^2 coefficients; null: v = 1
    int weight_deg;
    int32_t cell;        // the splat's cell (duplex), -1 when none
};

// Inputs of L::N splats, one per lane (SplatIn's values; sh[i * 3 + c] and weight_sh[i] as lanes).
template <class L>
struct SplatInLanes {
    typename L::F mean[3], scale[3], quat[4], opacity, filter_3d;
    const typename L::F* sh;
    const typename L::F* weight_sh;  // null: v = 1
    int weight_deg;
};

// Outputs of L::N splats: Splat2D's fields but log_min_alpha (log_min_alpha(lane_opacity), one lane at a time, with
// libm's logf as on one splat) and cell (the caller's).
template <class L>
struct Splat2DLanes {
    typename L::F xy[2], depth, opacity, conic[3], color[3], v1[2], sigma1, sigma2, inv_sigma1, inv_sigma2, radius;
    float min_alpha;
    GBV_HDI float log_min_alpha(float lane_opacity) const { return logf(min_alpha / lane_opacity); }
};

// View-space position R m + t of a world point; false behind the near plane (z <= 0.2, KERNELS.md §0.4). An
// orthographic camera culls the same way: it sees what lies in front of its image plane (z = 0) by more than the
// near distance, and sorts by the same view-space z.
template <class L>
GBV_HD typename L::M view_point(const CameraParams& cam, const typename L::F m[3], typename L::F pv[3]) {
    const float* R = cam.R;
    for (int i = 0; i < 3; ++i)
        pv[i] = L::mul_rn(L::set(R[i * 3]), m[0]) + L::mul_rn(L::set(R[i * 3 + 1]), m[1]) +
                L::mul_rn(L::set(R[i * 3 + 2]), m[2]) + L::set(cam.t[i]);
    return pv[2] > L::set(cam.near_plane);
}

// Screen position of the view-space point pv (perspective: fx X/Z + cx; orthographic: fx X + cx) and the tiles of
// the box with half sides h around it (getRect); false when a value is not finite or no tile is touched.
template <class L>
GBV_HD typename L::M screen_footprint(const CameraParams& cam, const typename L::F pv[3], const typename L::F h[2],
                                      int grid_x, int grid_y, typename L::F xy[2], TileRectLanes<L>* rect) {
    if (cam.projection == ORTHOGRAPHIC) {
        xy[0] = L::mul_rn(L::set(cam.fx), pv[0]) + L::set(cam.cx);
        xy[1] = L::mul_rn(L::set(cam.fy), pv[1]) + L::set(cam.cy);
    } else {
        xy[0] = L::set(cam.fx) * pv[0] / pv[2] + L::set(cam.cx);
        xy[1] = L::set(cam.fy) * pv[1] / pv[2] + L::set(cam.cy);
    }
    const typename L::M finite =
        L::and_(L::and_(L::finite(xy[0]), L::finite(xy[1])), L::and_(L::finite(h[0]), L::finite(h[1])));
    if (!L::any(finite)) return finite;
    *rect = tile_rect<L>(xy, h, grid_x, grid_y);
    return L::and_(finite, L::and_(L::gti(rect->x1, rect->x0), L::gti(rect->y1, rect->y0)));
}

// Preprocess one splat per lane for `mode`; returns the lanes that survive: a splat is culled when it is behind the
// near plane, degenerate, invisible, or touching no tile. wsr and duplex (KERNELS.md §7.2, §8.3) keep the 3DGS +0.3
// dilation and 3-sigma radius and fold the view weight and the optional depth correction into the opacity:
// o' = o * (v * (depth_correct ? 1 - z/sigma : 1)), culled when z >= sigma (depth_correct), v * dc <= 0 or
// o' < 1/255. The outputs of culled lanes are unspecified.
template <class L>
GBV_HD typename L::M preprocess_splat(const SplatInLanes<L>& in, int sh_deg, const CameraParams& cam, Mode mode,
                                      const OitParams& oit, int grid_x, int grid_y, Splat2DLanes<L>* out,
                                      TileRectLanes<L>* rect) {
    using F = typename L::F;
    using M = typename L::M;
    const F* m = in.mean;
    F pv[3];
    M ok = view_point<L>(cam, m, pv);
    if (!L::any(ok)) return ok;
    // SH and view-weight direction: from the eye to the splat; an orthographic camera's rays are parallel, so every
    // splat is seen along the camera's forward axis (row 2 of R)
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    F dir[3] = {ortho ? L::set(cam.R[6]) : m[0] - L::set(cam.campos[0]),
                ortho ? L::set(cam.R[7]) : m[1] - L::set(cam.campos[1]),
                ortho ? L::set(cam.R[8]) : m[2] - L::set(cam.campos[2])};
    const F dn = L::sqrt(L::mul_rn(dir[0], dir[0]) + L::mul_rn(dir[1], dir[1]) + L::mul_rn(dir[2], dir[2]));
    const M dpos = dn > L::set(0.0f);
    dir[0] = L::select(dpos, dir[0] / dn, L::set(0.0f));
    dir[1] = L::select(dpos, dir[1] / dn, L::set(0.0f));
    dir[2] = L::select(dpos, dir[2] / dn, L::set(1.0f));

    // Mip-Splatting 3D filter (applied in every mode when present): scales grow, opacity compensates.
    F s[3];
    F opacity = in.opacity;
    const M filtered = in.filter_3d > L::set(0.0f);
    if (L::any(filtered)) {
        const F f2 = L::mul_rn(in.filter_3d, in.filter_3d);
        F ratio = L::set(1.0f);
        for (int i = 0; i < 3; ++i) {
            const F s2 = L::mul_rn(in.scale[i], in.scale[i]);
            s[i] = L::select(filtered, L::sqrt(s2 + f2), in.scale[i]);
            ratio = ratio * (s2 / (s2 + f2));
        }
        opacity = L::select(filtered, opacity * L::sqrt(ratio), opacity);
    } else {
        for (int i = 0; i < 3; ++i) s[i] = in.scale[i];
    }

    F cov3[6], cov[3];
    covariance_3d<L>(in.quat, s, cov3);
    project_covariance<L>(cam, cov3, pv, cov);

    float sigmas = RADIUS_SIGMAS_3DGS;
    float min_alpha = MIN_ALPHA_3DGS;
    if (mode == SCALAR) {
        cov[0] = cov[0] + L::set(DILATION_3DGS);
        cov[2] = cov[2] + L::set(DILATION_3DGS);
    } else if (mode == MIP) {
        const F eps = L::set(1e-6f);
        const F det0 = L::fmax(eps, L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]));
        cov[0] = cov[0] + L::set(MIP_KERNEL_SIZE);
        cov[2] = cov[2] + L::set(MIP_KERNEL_SIZE);
        const F det1 = L::fmax(eps, L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]));
        const F coef = L::select(L::or_(det0 <= eps, det1 <= eps), L::set(0.0f),
                                 L::sqrt(det0 / (det1 + eps) + eps));
        opacity = opacity * coef;
    } else if (mode == GAUSSIAN_BLENDING) {
        sigmas = RADIUS_SIGMAS_GB;
        min_alpha = MIN_ALPHA_GB;
    } else if (mode == WSR || mode == DUPLEX) {
        cov[0] = cov[0] + L::set(DILATION_3DGS);
        cov[2] = cov[2] + L::set(DILATION_3DGS);
        F w = in.weight_sh ? sh_to_weight<L>(in.weight_sh, sh_deg < in.weight_deg ? sh_deg : in.weight_deg, dir)
                           : L::set(1.0f);
        if (oit.depth_correct) {
            ok = L::and_(ok, pv[2] < L::set(oit.sigma));
            w = w * (L::set(1.0f) - pv[2] / L::set(oit.sigma));
        }
        ok = L::and_(ok, w > L::set(0.0f));
        opacity = opacity * w;
    }
    // alpha = opacity * g <= opacity would be skipped anyway
    ok = L::and_(ok, opacity >= L::set(min_alpha));
    if (!L::any(ok)) return ok;

    const F det = L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]);
    ok = L::and_(ok, L::and_(det > L::set(0.0f), L::finite(det)));
    if (!L::any(ok)) return ok;
    const F inv = L::set(1.0f) / det;

    const F r = splat_radius<L>(cov[0], cov[2], det, sigmas);
    F half[2];
    cutoff_half_sides<L>(mode, cov, det, opacity, min_alpha, r, half);
    ok = L::and_(ok, screen_footprint<L>(cam, pv, half, grid_x, grid_y, out->xy, rect));
    if (!L::any(ok)) return ok;

    out->depth = pv[2];
    out->opacity = opacity;
    out->min_alpha = min_alpha;
    out->conic[0] = cov[2] * inv;
    out->conic[1] = L::neg(cov[1]) * inv;
    out->conic[2] = cov[0] * inv;
    eigen_2d<L>(cov[0], cov[1], cov[2], det, &out->sigma1, &out->sigma2, out->v1);
    out->inv_sigma1 = L::set(1.0f) / out->sigma1;
    out->inv_sigma2 = L::set(1.0f) / out->sigma2;
    out->radius = r;
    sh_to_rgb<L>(in.sh, sh_deg, dir, out->color);
    return ok;
}

// One splat (Lanes1): CUDA's, the scalar CPU path's and the GLSL port's signature.
GBV_HD bool preprocess_splat(const SplatIn& in, int sh_deg, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int grid_x, int grid_y, Splat2D* out, TileRect* rect) {
    const SplatInLanes<Lanes1> l{{in.mean[0], in.mean[1], in.mean[2]},
                                 {in.scale[0], in.scale[1], in.scale[2]},
                                 {in.quat[0], in.quat[1], in.quat[2], in.quat[3]},
                                 in.opacity,
                                 in.filter_3d,
                                 in.sh,
                                 in.weight_sh,
                                 in.weight_deg};
    Splat2DLanes<Lanes1> o;
    TileRectLanes<Lanes1> r;
    if (!preprocess_splat<Lanes1>(l, sh_deg, cam, mode, oit, grid_x, grid_y, &o, &r)) return false;
    *rect = TileRect{r.x0, r.y0, r.x1, r.y1};
    out->xy = Vec2{o.xy[0], o.xy[1]};
    out->depth = o.depth;
    out->opacity = o.opacity;
    out->log_min_alpha = o.log_min_alpha(o.opacity);
    for (int c = 0; c < 3; ++c) out->conic[c] = o.conic[c];
    for (int c = 0; c < 3; ++c) out->color[c] = o.color[c];
    out->v1 = Vec2{o.v1[0], o.v1[1]};
    out->sigma1 = o.sigma1;
    out->sigma2 = o.sigma2;
    out->inv_sigma1 = o.inv_sigma1;
    out->inv_sigma2 = o.inv_sigma2;
    out->radius = o.radius;
    out->cell = in.cell;
    return true;
}

// A Duplex-GS cell: an ellipsoid (centre, scales, unit (w,x,y,z) rotation) that covers its splats.
struct CellIn {
    const float* mean;
    const float* scale;
    const float* quat;
};

// Screen-space proxy of a cell: position, view-space depth (the sort key) and radius.
struct Cell2D {
    Vec2 xy;
    float depth;
    float radius;
};

// Project a cell as Duplex-GS's preprocessCUDA_anchor does (KERNELS.md §8.3): near cull, EWA projection with
// the +0.3 dilation, radius ceil(2 sqrt(lambda1)) (the splats use 3), tile rectangle; false when culled.
GBV_HD bool preprocess_cell(const CellIn& in, const CameraParams& cam, int grid_x, int grid_y, Cell2D* out,
                            TileRect* rect) {
    using L = Lanes1;
    const float m[3] = {in.mean[0], in.mean[1], in.mean[2]};
    float pv[3];
    if (!view_point<L>(cam, m, pv)) return false;
    const float q[4] = {in.quat[0], in.quat[1], in.quat[2], in.quat[3]}, s[3] = {in.scale[0], in.scale[1], in.scale[2]};
    float cov3[6], cov[3];
    covariance_3d<L>(q, s, cov3);
    project_covariance<L>(cam, cov3, pv, cov);
    cov[0] += DILATION_3DGS;
    cov[2] += DILATION_3DGS;
    const float det = mul_rn(cov[0], cov[2]) - mul_rn(cov[1], cov[1]);
    if (!(det > 0.0f) || !finitef(det)) return false;
    const float r = splat_radius<L>(cov[0], cov[2], det, DUPLEX_CELL_SIGMAS);
    const float h[2] = {r, r};
    float xy[2];
    TileRectLanes<L> t;
    if (!screen_footprint<L>(cam, pv, h, grid_x, grid_y, xy, &t)) return false;
    *rect = TileRect{t.x0, t.y0, t.x1, t.y1};
    out->xy = Vec2{xy[0], xy[1]};
    out->depth = pv[2];
    out->radius = r;
    return true;
}

}  // namespace gbv
