// Per-splat preprocess: cull, covariance, EWA projection, per-mode 2D filter, eigen-decomposition,
// colour from SH, tile rectangle. One function for every backend (KERNELS.md §0, §2, §4, §6.2).
#pragma once

#include "common.h"
#include "footprint.h"
#include "lanes.h"
#include "sh.h"
#include "view_filter.h"

namespace gbv {

// Every step is written once, as a template over a lane type L (lanes.h) like blend.h's: L::F holds one float per
// splat lane, L::M one flag per lane, so the same source compiles to the one-splat functions (Lanes1: CUDA, the GLSL
// port's reference and the scalar CPU path) and to the CPU's vector preprocess (native/cpu/preprocess_isa.cpp, 8 or
// 16 splats at once). Culling is a lane mask; a lane culled early computes on and is dropped at the end, and the work
// stops when no lane is left. Every lane type computes the same IEEE operations in the same order (its mul_rn,
// fmin/fmax, frexp and ceil are libm's, bit for bit), so the vector preprocess is bit-identical to the scalar one.
// The one-splat wrappers keep the signatures CUDA and the GLSL port use. SH evaluation is sh.h, the 2D footprint
// (eigen-decomposition, radius, cutoff box, tile rectangle) footprint.h.

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
        scalar_filter<L>(oit, cov, opacity, ok);
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
