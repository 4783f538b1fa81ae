// The per-camera stage of the preprocess (preprocess.h): what does not depend on the blending mode, computed once per
// camera and shared by every mode's finish (preprocess_finish): near cull, view-space position and depth, the
// Mip-Splatting 3D filter, the 3D covariance and its EWA projection before the mode's 2D filter, the screen position,
// and the SH colour. Lane templates like preprocess.h's (lanes.h): every lane type computes the same IEEE
// operations in the same order, and a stage stored as floats and loaded again is exact, so a mode's finish of a
// stored stage is bit-identical to preprocess_splat (preprocess.h), which composes the two for one splat.
#pragma once

#include "common.h"
#include "lanes.h"
#include "sh.h"

namespace gbv {

// The viewer presets' rules that change the stage (stage_rules): a bit each.
constexpr int STAGE_DC_CLAMP = 1;  // sh_to_rgb's dc_clamp
constexpr int STAGE_RADIAL = 2;  // the depth (the sort key) is the distance from the eye (perspective)

// The stage rules of a frame: OitParams' dc_clamp and sort_radial, the presets' (of the modes their 2D filter applies
// to: view_filtered); 0 for every other mode. Part of every backend's stage key, like stage_reach.
GBV_HD int stage_rules(Mode mode, const OitParams& oit) {
    if (!view_filtered(mode)) return 0;
    return (oit.dc_clamp ? STAGE_DC_CLAMP : 0) | (oit.sort_radial ? STAGE_RADIAL : 0);
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
    const F R[9] = {one - L::mul_rn(two, yy + zz), two * (xy - rz), two * (xz + ry), two * (xy + rz),
                    one - L::mul_rn(two, xx + zz), two * (yz - rx), two * (xz - ry), two * (yz + rx),
                    one - L::mul_rn(two, xx + yy)};
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
            TS[r * 3 + c] =
                L::mul_rn(T[r * 3], S[c]) + L::mul_rn(T[r * 3 + 1], S[3 + c]) + L::mul_rn(T[r * 3 + 2], S[6 + c]);
    out[0] = L::mul_rn(TS[0], T[0]) + L::mul_rn(TS[1], T[1]) + L::mul_rn(TS[2], T[2]);
    out[1] = L::mul_rn(TS[0], T[3]) + L::mul_rn(TS[1], T[4]) + L::mul_rn(TS[2], T[5]);
    out[2] = L::mul_rn(TS[3], T[3]) + L::mul_rn(TS[4], T[4]) + L::mul_rn(TS[5], T[5]);
}

// Inputs of one splat (activated parameters, see gbviewer.Scene).
struct SplatIn {
    const float* mean;  // 3
    const float* scale;  // 3
    const float* quat;  // 4 (w, x, y, z), unit
    float opacity;
    const float* sh;  // K*3
    float filter_3d;  // 0 when the scene has none
    const float* weight_sh;  // sort-free view weight, weight_deg's (deg+1)^2 coefficients; null: v = 1
    int weight_deg;
    int32_t cell;  // the splat's cell (duplex), -1 when none
};

// Inputs of L::N splats, one per lane (SplatIn's values; sh[i * 3 + c] and weight_sh[i] as lanes).
template <class L>
struct SplatInLanes {
    typename L::F mean[3], scale[3], quat[4], opacity, filter_3d;
    const typename L::F* sh;
    const typename L::F* weight_sh;  // null: v = 1
    int weight_deg;
};

// Mip-Splatting 3D filter (applied in every mode when present): the scales grow to sqrt(s^2 + f^2), the opacity
// scales by sqrt(prod s^2 / (s^2 + f^2)).
template <class L>
GBV_HD void filter_3d_scales(const SplatInLanes<L>& in, typename L::F s[3], typename L::F* opacity) {
    using F = typename L::F;
    const typename L::M filtered = in.filter_3d > L::set(0.0f);
    if (L::any(filtered)) {
        const F f2 = L::mul_rn(in.filter_3d, in.filter_3d);
        F ratio = L::set(1.0f);
        for (int i = 0; i < 3; ++i) {
            const F s2 = L::mul_rn(in.scale[i], in.scale[i]);
            s[i] = L::select(filtered, L::sqrt(s2 + f2), in.scale[i]);
            ratio = ratio * (s2 / (s2 + f2));
        }
        *opacity = L::select(filtered, *opacity * L::sqrt(ratio), *opacity);
    } else {
        for (int i = 0; i < 3; ++i) s[i] = in.scale[i];
    }
}

// View-space position R m + t of a world point; false behind the near plane (z <= 0.2,
// docs/modes.md#culling-radius-tiles). An orthographic camera culls the same way: it sees what lies in front of its
// image plane (z = 0) by more than the near distance, and sorts by the same view-space z.
template <class L>
GBV_HD typename L::M view_point(const CameraParams& cam, const typename L::F m[3], typename L::F pv[3]) {
    const float* R = cam.R;
    for (int i = 0; i < 3; ++i)
        pv[i] = L::mul_rn(L::set(R[i * 3]), m[0]) + L::mul_rn(L::set(R[i * 3 + 1]), m[1]) +
                L::mul_rn(L::set(R[i * 3 + 2]), m[2]) + L::set(cam.t[i]);
    return pv[2] > L::set(cam.near_plane);
}

// Unit direction from the eye to the world point m, for the SH colour and the view weight; an orthographic camera's
// rays are parallel, so every splat is seen along the camera's forward axis (row 2 of R).
template <class L>
GBV_HD void view_direction(const CameraParams& cam, const typename L::F m[3], typename L::F dir[3]) {
    using F = typename L::F;
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    dir[0] = ortho ? L::set(cam.R[6]) : m[0] - L::set(cam.campos[0]);
    dir[1] = ortho ? L::set(cam.R[7]) : m[1] - L::set(cam.campos[1]);
    dir[2] = ortho ? L::set(cam.R[8]) : m[2] - L::set(cam.campos[2]);
    const F dn = L::sqrt(L::mul_rn(dir[0], dir[0]) + L::mul_rn(dir[1], dir[1]) + L::mul_rn(dir[2], dir[2]));
    const typename L::M dpos = dn > L::set(0.0f);
    dir[0] = L::select(dpos, dir[0] / dn, L::set(0.0f));
    dir[1] = L::select(dpos, dir[1] / dn, L::set(0.0f));
    dir[2] = L::select(dpos, dir[2] / dn, L::set(1.0f));
}

// Screen position of the view-space point pv (perspective: fx X/Z + cx; orthographic: fx X + cx).
template <class L>
GBV_HD void screen_position(const CameraParams& cam, const typename L::F pv[3], typename L::F xy[2]) {
    if (cam.projection == ORTHOGRAPHIC) {
        xy[0] = L::mul_rn(L::set(cam.fx), pv[0]) + L::set(cam.cx);
        xy[1] = L::mul_rn(L::set(cam.fy), pv[1]) + L::set(cam.cy);
    } else {
        xy[0] = L::set(cam.fx) * pv[0] / pv[2] + L::set(cam.cx);
        xy[1] = L::set(cam.fy) * pv[1] / pv[2] + L::set(cam.cy);
    }
}

// The stage of L::N splats: screen position, view-space depth, opacity after the 3D filter, the projected 2D
// covariance (a, b, c) before the mode's filter, and the SH colour (stage_color; the CPU stores it only where
// stage_on_screen holds).
template <class L>
struct StageLanes {
    typename L::F xy[2], depth, opacity, cov[3], color[3];
};

// One splat's stored stage (StageLanes): screen position, depth, opacity after the 3D filter, the 2D covariance
// before the mode's filter, and the SH colour (computed only where stage_on_screen holds). The CPU and CUDA keep
// one per splat while the camera holds; the GLSL port stores the same fields (preprocess_stage.glsl: pack_stage).
struct StageSplat {
    float xy[2], depth, opacity, cov[3], color[3];
};

// The stage of one splat per lane but its colour; returns the lanes in front of the near plane (the others'
// outputs are unspecified). The depth is view-space z, or with STAGE_RADIAL in `rules` and a perspective camera the
// distance from the eye.
template <class L>
GBV_HD typename L::M preprocess_stage(const SplatInLanes<L>& in, const CameraParams& cam, int rules,
                                      StageLanes<L>* st) {
    using F = typename L::F;
    F pv[3];
    const typename L::M ok = view_point<L>(cam, in.mean, pv);
    if (!L::any(ok)) return ok;
    F s[3];
    F opacity = in.opacity;
    filter_3d_scales<L>(in, s, &opacity);
    F cov3[6];
    covariance_3d<L>(in.quat, s, cov3);
    project_covariance<L>(cam, cov3, pv, st->cov);
    st->depth = pv[2];
    if ((rules & STAGE_RADIAL) && cam.projection != ORTHOGRAPHIC)
        st->depth = L::sqrt(L::mul_rn(pv[0], pv[0]) + L::mul_rn(pv[1], pv[1]) + L::mul_rn(pv[2], pv[2]));
    st->opacity = opacity;
    screen_position<L>(cam, pv, st->xy);
    return ok;
}

// The stage's colour: SH of degree sh_deg seen from the eye (its base colour clamped with STAGE_DC_CLAMP in `rules`).
template <class L>
GBV_HD void stage_color(const SplatInLanes<L>& in, int sh_deg, int rules, const CameraParams& cam,
                        typename L::F color[3]) {
    typename L::F dir[3];
    view_direction<L>(cam, in.mean, dir);
    sh_to_rgb<L>(in.sh, sh_deg, dir, (rules & STAGE_DC_CLAMP) != 0, color);
}

// The reach a frame's stage serves (stage_on_screen, every backend's stage key): the largest diagonal the frame's
// 2D filter adds, the scalar mode's view filter (dilation + pre-dilation), every other mode at most DILATION_3DGS
// (preprocess_finish); eval3d infinite (every splat in front of the near plane is kept: the 2D covariance does not
// bound its footprint).
GBV_HD float stage_reach(Mode mode, const OitParams& oit) {
    if (mode == EVAL3D) return INFINITY;  // its footprint is the ray's (ray3d.h), not the 2D covariance's: keep all
    const float filter = view_filtered(mode) ? oit.dilation + oit.pre_dilation : 0.0f;
    return filter > DILATION_3DGS ? filter : DILATION_3DGS;
}

// Lanes of a stage that some mode may keep: false only where every mode's finish culls the splat for touching no
// tile of a grid_x x grid_y grid. Every mode's half sides are at most its radius ceil(k sqrt(lambda1)) with
// k <= RADIUS_SIGMAS_GB and lambda1 = mid + sqrt(max(0.1, mid^2 - det)) <= a + c + 0.32 of its filtered covariance,
// whose a + c is at most the stage's + 2 reach (reach: the largest diagonal any of the stage's modes adds, at least
// DILATION_3DGS: stage_reach) (det <= 0 is culled in every mode): h <= 3.34 sqrt(a + c + 2 reach + 0.4) + 2 with room
// for float rounding. A splat whose box misses the image by that much (getRect: x + h < 1.5 or x - h >= 16 grid_x +
// 0.5) is culled everywhere. NaN bounds or positions keep the lane (the finish decides).
template <class L>
GBV_HD typename L::M stage_on_screen(const StageLanes<L>& st, int grid_x, int grid_y, float reach) {
    using F = typename L::F;
    const F h = L::set(3.34f) * L::sqrt(st.cov[0] + st.cov[2] + L::set(2.0f * reach + 0.4f)) + L::set(2.0f);
    const typename L::M off = L::or_(L::or_(st.xy[0] + h<L::set(0.0f), st.xy[0] - h> L::set(TILE * grid_x + 1.0f)),
                                     L::or_(st.xy[1] + h<L::set(0.0f), st.xy[1] - h> L::set(TILE * grid_y + 1.0f)));
    return L::and_not(L::first_n(L::N), off);
}

}  // namespace gbv
