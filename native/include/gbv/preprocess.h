// Per-splat preprocess: cull, covariance, EWA projection, per-mode 2D filter, eigen-decomposition,
// colour from SH, tile rectangle. One function for every backend (KERNELS.md §0, §2, §4, §6.2).
#pragma once

#include "common.h"

namespace gbv {

constexpr float SH_C0 = 0.28209479177387814f;
constexpr float SH_C1 = 0.4886025119029199f;
// Scalars rather than arrays: nvcc cannot read namespace-scope constexpr arrays in device code.
constexpr float SH_C2_0 = 1.0925484305920792f, SH_C2_1 = -1.0925484305920792f, SH_C2_2 = 0.31539156525252005f,
                SH_C2_3 = -1.0925484305920792f, SH_C2_4 = 0.5462742152960396f;
constexpr float SH_C3_0 = -0.5900435899266435f, SH_C3_1 = 2.890611442640554f, SH_C3_2 = -0.4570457994644658f,
                SH_C3_3 = 0.3731763325901154f, SH_C3_4 = -0.4570457994644658f, SH_C3_5 = 1.445305721320277f,
                SH_C3_6 = -0.5900435899266435f;

// Real SH basis of degree `deg` (0..3) at the unit direction `dir`, in the 3DGS order and signs; returns the
// number of coefficients used, (deg + 1)^2.
GBV_HD int sh_basis(int deg, Vec3 dir, float basis[16]) {
    const float x = dir.x, y = dir.y, z = dir.z;
    basis[0] = SH_C0;
    if (deg < 1) return 1;
    basis[1] = -SH_C1 * y;
    basis[2] = SH_C1 * z;
    basis[3] = -SH_C1 * x;
    if (deg < 2) return 4;
    const float xx = mul_rn(x, x), yy = mul_rn(y, y), zz = mul_rn(z, z), xy = x * y, yz = y * z, xz = x * z;
    basis[4] = SH_C2_0 * xy;
    basis[5] = SH_C2_1 * yz;
    basis[6] = SH_C2_2 * (mul_rn(2.0f, zz) - xx - yy);
    basis[7] = SH_C2_3 * xz;
    basis[8] = SH_C2_4 * (xx - yy);
    if (deg < 3) return 9;
    basis[9] = SH_C3_0 * y * (mul_rn(3.0f, xx) - yy);
    basis[10] = SH_C3_1 * xy * z;
    basis[11] = SH_C3_2 * y * (mul_rn(4.0f, zz) - xx - yy);
    basis[12] = SH_C3_3 * z * (mul_rn(2.0f, zz) - mul_rn(3.0f, xx) - mul_rn(3.0f, yy));
    basis[13] = SH_C3_4 * x * (mul_rn(4.0f, zz) - xx - yy);
    basis[14] = SH_C3_5 * z * (xx - yy);
    basis[15] = SH_C3_6 * x * (xx - mul_rn(3.0f, yy));
    return 16;
}

// View-dependent colour from SH coefficients sh[K][3] (DC first), as computeColorFromSH:
// +0.5 offset, clamped at 0 from below only.
GBV_HD void sh_to_rgb(const float* sh, int deg, Vec3 dir, float out[3]) {
    float basis[16];
    const int k = sh_basis(deg, dir, basis);
    for (int c = 0; c < 3; ++c) {
        float v = 0.5f;
        for (int i = 0; i < k; ++i) v += mul_rn(basis[i], sh[i * 3 + c]);
        out[c] = fmaxf(v, 0.0f);
    }
}

// Sort-free GS's view-dependent weight v_i (KERNELS.md §7.3): a 1-channel SH w[K] (f_do_0, f_ro_*), the raw
// sum: no +0.5, no clamp (non-positive weights are culled by the caller).
GBV_HD float sh_to_weight(const float* w, int deg, Vec3 dir) {
    float basis[16];
    const int k = sh_basis(deg, dir, basis);
    float v = 0.0f;
    for (int i = 0; i < k; ++i) v += mul_rn(basis[i], w[i]);
    return v;
}

// 3D covariance Sigma = R S S^T R^T (upper triangle: xx, xy, xz, yy, yz, zz) from a unit (w,x,y,z)
// quaternion and per-axis scales (eq. 1).
GBV_HD void covariance_3d(const float* q, const float* s, float cov[6]) {
    const float r = q[0], x = q[1], y = q[2], z = q[3];
    const float xx = mul_rn(x, x), yy = mul_rn(y, y), zz = mul_rn(z, z), xy = mul_rn(x, y), xz = mul_rn(x, z),
                yz = mul_rn(y, z), rx = mul_rn(r, x), ry = mul_rn(r, y), rz = mul_rn(r, z);
    const float R[9] = {1.f - mul_rn(2.f, yy + zz), 2.f * (xy - rz),             2.f * (xz + ry),
                        2.f * (xy + rz),             1.f - mul_rn(2.f, xx + zz), 2.f * (yz - rx),
                        2.f * (xz - ry),             2.f * (yz + rx),             1.f - mul_rn(2.f, xx + yy)};
    float M[9];  // M = R S
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) M[i * 3 + j] = R[i * 3 + j] * s[j];
    cov[0] = mul_rn(M[0], M[0]) + mul_rn(M[1], M[1]) + mul_rn(M[2], M[2]);
    cov[1] = mul_rn(M[0], M[3]) + mul_rn(M[1], M[4]) + mul_rn(M[2], M[5]);
    cov[2] = mul_rn(M[0], M[6]) + mul_rn(M[1], M[7]) + mul_rn(M[2], M[8]);
    cov[3] = mul_rn(M[3], M[3]) + mul_rn(M[4], M[4]) + mul_rn(M[5], M[5]);
    cov[4] = mul_rn(M[3], M[6]) + mul_rn(M[4], M[7]) + mul_rn(M[5], M[8]);
    cov[5] = mul_rn(M[6], M[6]) + mul_rn(M[7], M[7]) + mul_rn(M[8], M[8]);
}

// EWA projection of a 3D covariance to screen space (eq. 3): J W Sigma W^T J^T, with the view-space
// point clamped to 1.3x the frustum for the Jacobian only (computeCov2D). Returns (a, b, c).
GBV_HD void project_covariance(const CameraParams& cam, const float cov3[6], const float pv[3], float out[3]) {
    const float tz = pv[2];
    const float tx = clampf(pv[0] / tz, -cam.lim_x_neg, cam.lim_x_pos) * tz;
    const float ty = clampf(pv[1] / tz, -cam.lim_y_neg, cam.lim_y_pos) * tz;
    const float j00 = cam.fx / tz, j02 = -cam.fx * tx / (tz * tz);
    const float j11 = cam.fy / tz, j12 = -cam.fy * ty / (tz * tz);
    const float* W = cam.R;
    // T = J W (2x3)
    float T[6];
    for (int c = 0; c < 3; ++c) {
        T[c] = mul_rn(j00, W[c]) + mul_rn(j02, W[6 + c]);
        T[3 + c] = mul_rn(j11, W[3 + c]) + mul_rn(j12, W[6 + c]);
    }
    const float S[9] = {cov3[0], cov3[1], cov3[2], cov3[1], cov3[3], cov3[4], cov3[2], cov3[4], cov3[5]};
    float TS[6];
    for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c)
            TS[r * 3 + c] = mul_rn(T[r * 3], S[c]) + mul_rn(T[r * 3 + 1], S[3 + c]) + mul_rn(T[r * 3 + 2], S[6 + c]);
    out[0] = mul_rn(TS[0], T[0]) + mul_rn(TS[1], T[1]) + mul_rn(TS[2], T[2]);
    out[1] = mul_rn(TS[0], T[3]) + mul_rn(TS[1], T[4]) + mul_rn(TS[2], T[5]);
    out[2] = mul_rn(TS[3], T[3]) + mul_rn(TS[4], T[4]) + mul_rn(TS[5], T[5]);
}

// Eigen-decomposition of a 2x2 covariance (a, b, c): sigma = sqrt(eigenvalues) and the unit major
// eigenvector. lambda2 = det / lambda1 equals mid - sqrt(mid^2 - det) exactly and avoids cancellation;
// the eigenvector is taken from whichever of its two formulas is better conditioned, so isotropic
// splats get a valid axis instead of normalize(0, 0).
GBV_HD void eigen_2d(float a, float b, float c, float det, float* sigma1, float* sigma2, Vec2* v1) {
    const float mid = 0.5f * (a + c);
    const float root = sqrtf(fmaxf(0.0f, mid * mid - det));
    const float l1 = mid + root;
    const float l2 = det / l1;
    *sigma1 = sqrtf(l1);
    *sigma2 = sqrtf(l2);
    Vec2 e1 = {b, l1 - a}, e2 = {l1 - c, b};
    const float n1 = dot(e1, e1), n2 = dot(e2, e2);
    Vec2 e = n1 >= n2 ? e1 : e2;
    const float n = fmaxf(n1, n2);
    *v1 = n > 1e-30f ? (1.0f / sqrtf(n)) * e : Vec2{1.0f, 0.0f};
}

// Screen-space bounding radius in pixels: ceil(k * sqrt(max eigenvalue)) with the published
// max(0.1, mid^2 - det) floor.
GBV_HD float splat_radius(float a, float c, float det, float sigmas) {
    const float mid = mul_rn(0.5f, a + c);
    const float lmax = mid + sqrtf(fmaxf(0.1f, mul_rn(mid, mid) - det));
    return ceilf(sigmas * sqrtf(lmax));
}

// ln(x) for x >= 1, from above, by basic float operations only, so that every backend computes the same value (logf
// differs in its last bit between libm, CUDA and GLSL): x = m 2^e with m in [1, 2) (exact), ln m <= t - t^2/2 + t^3/3
// with t = m - 1 (the alternating series cut after a positive term; at most 0.14 above).
GBV_HD float log_upper(float x) {
    int e;
    const float m = 2.0f * frexpf(x, &e);  // x = m 2^(e - 1)
    const float t = m - 1.0f, t2 = mul_rn(t, t);
    return mul_rn((float)(e - 1), 0.69314720f) + t - mul_rn(0.5f, t2) + mul_rn(mul_rn(t2, t), 0.33333334f);
}

// Half sides (x, y) of the screen box that binning gives a splat. scalar, mip, wsr and duplex skip a pixel where
// power < ln(min_alpha / opacity), i.e. outside the ellipse d^T Sigma^-1 d <= r2 = 2 ln(opacity / min_alpha), whose
// bounding box has half sides sqrt(r2 Sigma_xx) and sqrt(r2 Sigma_yy): widened for the blend's float rounding
// (relative 1e-5 + 1e-6 lambda1^2 / det, plus 0.02 px), rounded up to whole pixels, plus one pixel (getRect's upper
// edge takes a tile only when the box reaches 1 px into it: tight to the pixel, it would drop the tile's first row or
// column), and capped by the radius r (the published square): no tile a pixel could take the splat in is dropped.
// gaussian_blending (its windows move: the published 3.33 sigma square) and analytic (alpha integrated over the
// pixel): the radius.
GBV_HD Vec2 cutoff_half_sides(Mode mode, const float cov[3], float det, float opacity, float min_alpha, float r) {
    if (mode == GAUSSIAN_BLENDING || mode == ANALYTIC) return {r, r};
    // + 1e-6: the blend's threshold is logf(min_alpha / opacity), from the other quotient (up to ~2e-7 apart)
    const float r2 = mul_rn(2.0f, log_upper(opacity / min_alpha)) + 1e-6f;
    const float mid = mul_rn(0.5f, cov[0] + cov[2]);
    const float l1 = mid + sqrtf(fmaxf(0.0f, mul_rn(mid, mid) - det));
    const float grow = 1.00001f + mul_rn(1e-6f, mul_rn(l1, l1) / det);
    const float hx = ceilf(mul_rn(sqrtf(r2 * cov[0]), grow) + 0.02f) + 1.0f;
    const float hy = ceilf(mul_rn(sqrtf(r2 * cov[2]), grow) + 0.02f) + 1.0f;
    return {minf(hx, r), minf(hy, r)};  // minf: a NaN side becomes r
}

// Tiles touched by a splat at xy with half sides h (getRect, which has h = (r, r)), in the published integer-centre
// pixel convention (our xy minus 0.5). Empty when x1 <= x0 or y1 <= y0.
GBV_HD TileRect tile_rect(Vec2 xy, Vec2 h, int grid_x, int grid_y) {
    const float px = xy.x - 0.5f, py = xy.y - 0.5f;
    const float gx = (float)grid_x, gy = (float)grid_y;
    TileRect t;
    t.x0 = (int)clampf((px - h.x) / TILE, 0.0f, gx);
    t.y0 = (int)clampf((py - h.y) / TILE, 0.0f, gy);
    t.x1 = (int)clampf((px + h.x + TILE - 1) / TILE, 0.0f, gx);
    t.y1 = (int)clampf((py + h.y + TILE - 1) / TILE, 0.0f, gy);
    return t;
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

// View-space position R m + t of a world point; false behind the near plane (z <= 0.2, KERNELS.md §0.4).
GBV_HD bool view_point(const CameraParams& cam, const float* m, float pv[3]) {
    const float* R = cam.R;
    for (int i = 0; i < 3; ++i)
        pv[i] = mul_rn(R[i * 3], m[0]) + mul_rn(R[i * 3 + 1], m[1]) + mul_rn(R[i * 3 + 2], m[2]) + cam.t[i];
    return pv[2] > cam.near_plane;
}

// Screen position of the view-space point pv and the tiles of the box with half sides h around it (getRect); false
// when a value is not finite or no tile is touched.
GBV_HD bool screen_footprint(const CameraParams& cam, const float pv[3], Vec2 h, int grid_x, int grid_y, Vec2* xy,
                             TileRect* rect) {
    *xy = Vec2{cam.fx * pv[0] / pv[2] + cam.cx, cam.fy * pv[1] / pv[2] + cam.cy};
    if (!finitef(xy->x) || !finitef(xy->y) || !finitef(h.x) || !finitef(h.y)) return false;
    *rect = tile_rect(*xy, h, grid_x, grid_y);
    return rect->x1 > rect->x0 && rect->y1 > rect->y0;
}

// Preprocess one splat for `mode`; returns false when it is culled (behind the near plane, degenerate,
// invisible, or touching no tile). wsr and duplex (KERNELS.md §7.2, §8.3) keep the 3DGS +0.3 dilation and
// 3-sigma radius and fold the view weight and the optional depth correction into the opacity:
// o' = o * (v * (depth_correct ? 1 - z/sigma : 1)), culled when z >= sigma (depth_correct), v * dc <= 0 or
// o' < 1/255.
GBV_HD bool preprocess_splat(const SplatIn& in, int sh_deg, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int grid_x, int grid_y, Splat2D* out, TileRect* rect) {
    const float* m = in.mean;
    float pv[3];
    if (!view_point(cam, m, pv)) return false;
    Vec3 dir = {m[0] - cam.campos[0], m[1] - cam.campos[1], m[2] - cam.campos[2]};
    const float dn = sqrtf(mul_rn(dir.x, dir.x) + mul_rn(dir.y, dir.y) + mul_rn(dir.z, dir.z));
    dir = dn > 0.0f ? Vec3{dir.x / dn, dir.y / dn, dir.z / dn} : Vec3{0.0f, 0.0f, 1.0f};

    // Mip-Splatting 3D filter (applied in every mode when present): scales grow, opacity compensates.
    float s[3];
    float opacity = in.opacity;
    if (in.filter_3d > 0.0f) {
        const float f2 = mul_rn(in.filter_3d, in.filter_3d);
        float ratio = 1.0f;
        for (int i = 0; i < 3; ++i) {
            const float s2 = mul_rn(in.scale[i], in.scale[i]);
            s[i] = sqrtf(s2 + f2);
            ratio *= s2 / (s2 + f2);
        }
        opacity *= sqrtf(ratio);
    } else {
        for (int i = 0; i < 3; ++i) s[i] = in.scale[i];
    }

    float cov3[6], cov[3];
    covariance_3d(in.quat, s, cov3);
    project_covariance(cam, cov3, pv, cov);

    float sigmas = RADIUS_SIGMAS_3DGS;
    float min_alpha = MIN_ALPHA_3DGS;
    if (mode == SCALAR) {
        cov[0] += DILATION_3DGS;
        cov[2] += DILATION_3DGS;
    } else if (mode == MIP) {
        const float det0 = fmaxf(1e-6f, mul_rn(cov[0], cov[2]) - mul_rn(cov[1], cov[1]));
        cov[0] += MIP_KERNEL_SIZE;
        cov[2] += MIP_KERNEL_SIZE;
        const float det1 = fmaxf(1e-6f, mul_rn(cov[0], cov[2]) - mul_rn(cov[1], cov[1]));
        const float coef = (det0 <= 1e-6f || det1 <= 1e-6f) ? 0.0f : sqrtf(det0 / (det1 + 1e-6f) + 1e-6f);
        opacity *= coef;
    } else if (mode == GAUSSIAN_BLENDING) {
        sigmas = RADIUS_SIGMAS_GB;
        min_alpha = MIN_ALPHA_GB;
    } else if (mode == WSR || mode == DUPLEX) {
        cov[0] += DILATION_3DGS;
        cov[2] += DILATION_3DGS;
        float w = in.weight_sh ? sh_to_weight(in.weight_sh, sh_deg < in.weight_deg ? sh_deg : in.weight_deg, dir)
                               : 1.0f;
        if (oit.depth_correct) {
            if (!(pv[2] < oit.sigma)) return false;
            w *= 1.0f - pv[2] / oit.sigma;
        }
        if (!(w > 0.0f)) return false;
        opacity *= w;
    }
    if (!(opacity >= min_alpha)) return false;  // alpha = opacity * g <= opacity would be skipped anyway

    const float det = mul_rn(cov[0], cov[2]) - mul_rn(cov[1], cov[1]);
    if (!(det > 0.0f) || !finitef(det)) return false;
    const float inv = 1.0f / det;

    const float r = splat_radius(cov[0], cov[2], det, sigmas);
    Vec2 xy;
    const Vec2 half = cutoff_half_sides(mode, cov, det, opacity, min_alpha, r);
    if (!screen_footprint(cam, pv, half, grid_x, grid_y, &xy, rect)) return false;

    out->xy = xy;
    out->depth = pv[2];
    out->opacity = opacity;
    out->log_min_alpha = logf(min_alpha / opacity);
    out->conic[0] = cov[2] * inv;
    out->conic[1] = -cov[1] * inv;
    out->conic[2] = cov[0] * inv;
    eigen_2d(cov[0], cov[1], cov[2], det, &out->sigma1, &out->sigma2, &out->v1);
    out->inv_sigma1 = 1.0f / out->sigma1;
    out->inv_sigma2 = 1.0f / out->sigma2;
    out->radius = r;
    out->cell = in.cell;
    sh_to_rgb(in.sh, sh_deg, dir, out->color);
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
    const float* m = in.mean;
    float pv[3];
    if (!view_point(cam, m, pv)) return false;
    float cov3[6], cov[3];
    covariance_3d(in.quat, in.scale, cov3);
    project_covariance(cam, cov3, pv, cov);
    cov[0] += DILATION_3DGS;
    cov[2] += DILATION_3DGS;
    const float det = mul_rn(cov[0], cov[2]) - mul_rn(cov[1], cov[1]);
    if (!(det > 0.0f) || !finitef(det)) return false;
    const float r = splat_radius(cov[0], cov[2], det, DUPLEX_CELL_SIGMAS);
    if (!screen_footprint(cam, pv, Vec2{r, r}, grid_x, grid_y, &out->xy, rect)) return false;
    out->depth = pv[2];
    out->radius = r;
    return true;
}

}  // namespace gbv
