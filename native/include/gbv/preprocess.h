// Per-splat preprocess: cull, covariance, EWA projection, per-mode 2D filter, eigen-decomposition,
// colour from SH, tile rectangle (docs/modes.md#shared-pipeline). One function for every backend: the per-camera stage
// (preprocess_stage.h, shared by every mode) and the mode's finish (preprocess_finish); for one splat stage_splat and
// finish_splat, composed by preprocess_splat.
#pragma once

#include "common.h"
#include "footprint.h"
#include "lanes.h"
#include "preprocess_stage.h"
#include "sh.h"
#include "view_filter.h"

namespace gbv {

// Every step is written once, as a template over a lane type L (lanes.h) like blend.h's: L::F holds one float per
// splat lane, L::M one flag per lane, so the same source compiles to the one-splat functions (Lanes1: CUDA, the GLSL
// port's reference and the scalar CPU path) and to the CPU's vector preprocess (native/cpu/preprocess_isa.cpp, 8 or
// 16 splats at once; the CPU stores the stage per camera and runs each mode's finish on it). Culling is a lane mask; a
// lane culled early computes on and is dropped at the end, and the work stops when no lane is left. Every lane type
// computes the same IEEE operations in the same order (its mul_rn, fmin/fmax, frexp and ceil are libm's, bit for bit),
// so the vector preprocess is bit-identical to the scalar one. The one-splat wrappers keep the signatures CUDA and the
// GLSL port use. SH evaluation is sh.h, the 2D footprint (eigen-decomposition, radius, cutoff box, tile rectangle)
// footprint.h.

// Outputs of L::N splats: Splat2D's fields but log_min_alpha (log_min_alpha(lane_opacity), one lane at a time, with
// libm's logf as on one splat) and cell (the caller's). min_power: a preset's support cut (support_power); the blend
// skips powers below log_min_alpha, so the cut raises it.
template <class L>
struct Splat2DLanes {
    typename L::F xy[2], depth, opacity, conic[3], color[3], v1[2], sigma1, sigma2, inv_sigma1, inv_sigma2, radius;
    float min_alpha;
    float min_power;
    GBV_HDI float log_min_alpha(float lane_opacity) const { return maxf(logf(min_alpha / lane_opacity), min_power); }
};

// The tiles of the box with half sides h around the screen position xy (getRect, which has h = (r, r)); false when a
// value is not finite or no tile is touched.
template <class L>
GBV_HD typename L::M tile_footprint(const typename L::F xy[2], const typename L::F h[2], int grid_x, int grid_y,
                                    TileRectLanes<L>* rect) {
    const typename L::M finite =
        L::and_(L::and_(L::finite(xy[0]), L::finite(xy[1])), L::and_(L::finite(h[0]), L::finite(h[1])));
    if (!L::any(finite)) return finite;
    *rect = tile_rect<L>(xy, h, grid_x, grid_y);
    return L::and_(finite, L::and_(L::gti(rect->x1, rect->x0), L::gti(rect->y1, rect->y0)));
}

// Screen position of the view-space point pv and its tile footprint with half sides h (tile_footprint).
template <class L>
GBV_HD typename L::M screen_footprint(const CameraParams& cam, const typename L::F pv[3], const typename L::F h[2],
                                      int grid_x, int grid_y, typename L::F xy[2], TileRectLanes<L>* rect) {
    screen_position<L>(cam, pv, xy);
    return tile_footprint<L>(xy, h, grid_x, grid_y, rect);
}

// The mode's finish of one splat per lane from its stage st (the lanes `ok`; in: only mean, weight_sh and weight_deg
// are read, for the view weight): everything but the colour, which the caller takes from the stage. Returns the lanes
// that survive: a splat is culled when it is degenerate, invisible, or touching no tile. wsr and duplex
// (docs/modes.md#wsr, #duplex) keep the 3DGS +0.3 dilation and 3-sigma radius and fold the view weight and the optional
// depth correction into the opacity: o' = o * (v * (depth_correct ? 1 - z/sigma : 1)), culled when z >= sigma
// (depth_correct), v * dc <= 0 or o' < 1/255. The outputs of culled lanes are unspecified.
template <class L>
GBV_HD typename L::M preprocess_finish(const SplatInLanes<L>& in, const StageLanes<L>& st, typename L::M ok, int sh_deg,
                                       const CameraParams& cam, Mode mode, const OitParams& oit, int grid_x, int grid_y,
                                       Splat2DLanes<L>* out, TileRectLanes<L>* rect) {
    using F = typename L::F;
    F cov[3] = {st.cov[0], st.cov[1], st.cov[2]};
    F opacity = st.opacity;

    // the mode's 2D filter, opacity compensation, view weight and cut-off
    float sigmas = RADIUS_SIGMAS_3DGS;
    float min_alpha = MIN_ALPHA_3DGS;
    float min_power = -INFINITY;
    if (view_filtered(mode) || mode == STOPTHEPOP) {  // stopthepop blends 3DGS's 2D splats in its own order
        scalar_filter<L>(oit, cov, opacity, ok);
        min_power = support_power(oit);
    } else if (mode == MIP) {
        const F eps = L::set(1e-6f);
        const F det0 = L::fmax(eps, L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]));
        cov[0] = cov[0] + L::set(MIP_KERNEL_SIZE);
        cov[2] = cov[2] + L::set(MIP_KERNEL_SIZE);
        const F det1 = L::fmax(eps, L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]));
        const F coef = L::select(L::or_(det0 <= eps, det1 <= eps), L::set(0.0f), L::sqrt(det0 / (det1 + eps) + eps));
        opacity = opacity * coef;
    } else if (mode == GAUSSIAN_BLENDING) {
        sigmas = RADIUS_SIGMAS_GB;
        min_alpha = MIN_ALPHA_GB;
    } else if (mode == WSR || mode == DUPLEX) {
        cov[0] = cov[0] + L::set(DILATION_3DGS);
        cov[2] = cov[2] + L::set(DILATION_3DGS);
        F w = L::set(1.0f);
        if (in.weight_sh) {
            F dir[3];
            view_direction<L>(cam, in.mean, dir);
            w = sh_to_weight<L>(in.weight_sh, sh_deg < in.weight_deg ? sh_deg : in.weight_deg, dir);
        }
        if (oit.depth_correct) {
            ok = L::and_(ok, st.depth < L::set(oit.sigma));
            w = w * (L::set(1.0f) - st.depth / L::set(oit.sigma));
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
    ok = L::and_(ok, tile_footprint<L>(st.xy, half, grid_x, grid_y, rect));
    if (!L::any(ok)) return ok;

    out->xy[0] = st.xy[0];
    out->xy[1] = st.xy[1];
    out->depth = st.depth;
    out->opacity = opacity;
    out->min_alpha = min_alpha;
    out->min_power = min_power;
    out->conic[0] = cov[2] * inv;
    out->conic[1] = L::neg(cov[1]) * inv;
    out->conic[2] = cov[0] * inv;
    eigen_2d<L>(cov[0], cov[1], cov[2], det, &out->sigma1, &out->sigma2, out->v1);
    out->inv_sigma1 = L::set(1.0f) / out->sigma1;
    out->inv_sigma2 = L::set(1.0f) / out->sigma2;
    out->radius = r;
    return ok;
}

// One splat's stage (Lanes1; CUDA's stage kernel, the GLSL port's stage.comp): false behind the near plane or off
// screen in every mode whose 2D filter adds at most `reach` (stage_on_screen); the colour is computed only when true.
GBV_HD bool stage_splat(const SplatIn& in, int sh_deg, int rules, const CameraParams& cam, int grid_x, int grid_y,
                        float reach, StageSplat* out) {
    const SplatInLanes<Lanes1> l{{in.mean[0], in.mean[1], in.mean[2]},
                                 {in.scale[0], in.scale[1], in.scale[2]},
                                 {in.quat[0], in.quat[1], in.quat[2], in.quat[3]},
                                 in.opacity,
                                 in.filter_3d,
                                 in.sh,
                                 in.weight_sh,
                                 in.weight_deg};
    StageLanes<Lanes1> st;
    if (!preprocess_stage<Lanes1>(l, cam, rules, &st) || !stage_on_screen<Lanes1>(st, grid_x, grid_y, reach))
        return false;
    out->xy[0] = st.xy[0];
    out->xy[1] = st.xy[1];
    out->depth = st.depth;
    out->opacity = st.opacity;
    for (int c = 0; c < 3; ++c) out->cov[c] = st.cov[c];
    stage_color<Lanes1>(l, sh_deg, rules, cam, out->color);
    return true;
}

// The mode's finish of one splat's stored stage (Lanes1; CUDA's finish kernel): Splat2D and tile rectangle, the
// colour the stage's; false when culled. Of `in` only mean, weight_sh, weight_deg and cell are read (the others may be
// null).
GBV_HD bool finish_splat(const SplatIn& in, const StageSplat& stage, int sh_deg, const CameraParams& cam, Mode mode,
                         const OitParams& oit, int grid_x, int grid_y, Splat2D* out, TileRect* rect) {
    SplatInLanes<Lanes1> l{};
    for (int c = 0; c < 3; ++c) l.mean[c] = in.mean[c];
    l.weight_sh = in.weight_sh;
    l.weight_deg = in.weight_deg;
    StageLanes<Lanes1> st;
    st.xy[0] = stage.xy[0];
    st.xy[1] = stage.xy[1];
    st.depth = stage.depth;
    st.opacity = stage.opacity;
    for (int c = 0; c < 3; ++c) st.cov[c] = stage.cov[c];
    Splat2DLanes<Lanes1> o;
    TileRectLanes<Lanes1> r;
    if (!preprocess_finish<Lanes1>(l, st, true, sh_deg, cam, mode, oit, grid_x, grid_y, &o, &r)) return false;
    *rect = TileRect{r.x0, r.y0, r.x1, r.y1};
    out->xy = Vec2{o.xy[0], o.xy[1]};
    out->depth = o.depth;
    out->opacity = o.opacity;
    out->log_min_alpha = o.log_min_alpha(o.opacity);
    for (int c = 0; c < 3; ++c) out->conic[c] = o.conic[c];
    for (int c = 0; c < 3; ++c) out->color[c] = stage.color[c];
    out->v1 = Vec2{o.v1[0], o.v1[1]};
    out->sigma1 = o.sigma1;
    out->sigma2 = o.sigma2;
    out->inv_sigma1 = o.inv_sigma1;
    out->inv_sigma2 = o.inv_sigma2;
    out->radius = o.radius;
    out->cell = in.cell;
    out->id = -1;  // the caller's (the splat's index)
    return true;
}

// One splat for `mode` (Lanes1): its stage (stage_splat at the mode's stage_reach) and the mode's finish
// (finish_splat), as every backend's stored stage gives it.
GBV_HD bool preprocess_splat(const SplatIn& in, int sh_deg, const CameraParams& cam, Mode mode, const OitParams& oit,
                             int grid_x, int grid_y, Splat2D* out, TileRect* rect) {
    StageSplat st;
    if (!stage_splat(in, sh_deg, stage_rules(mode, oit), cam, grid_x, grid_y, stage_reach(mode, oit), &st))
        return false;
    return finish_splat(in, st, sh_deg, cam, mode, oit, grid_x, grid_y, out, rect);
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

// Project a cell as Duplex-GS's preprocessCUDA_anchor does (docs/modes.md#duplex): near cull, EWA projection with
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
