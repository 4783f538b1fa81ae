// The depth plane of the stochastic_popfree mode (stochastic.h): where a splat's fragment lies along each pixel's
// ray, for the depth test. Each backend computes it after the mode's finish, into a per-splat array beside the
// Splat2D (indexed by Splat2D::id), which the other modes neither compute nor read.
#pragma once

#include "common.h"
#include "lanes.h"
#include "preprocess_stage.h"

namespace gbv {

// (a, b, c, d): the plane along the ray of pixel (px, py) lies at key (a px + b py + c) / d (popfree_plane).
struct DepthPlane {
    float a, b, c, d;
};

// a . b of strided 3-vectors, and a b - c d, every product through mul_rn (common.h): the same bits on every path
GBV_HD float dot3_rn(const float* a, int sa, const float* b, int sb) {
    return mul_rn(a[0], b[0]) + mul_rn(a[sa], b[sb]) + mul_rn(a[2 * sa], b[2 * sb]);
}
GBV_HD float minor_rn(float a, float b, float c, float d) { return mul_rn(a, b) - mul_rn(c, d); }

// The depth plane of a splat with view-space mean pv and world covariance cov3 (upper triangle, as covariance_3d):
// the plane through the mean with normal Sigma_v^-1 dir, Sigma_v = R Sigma R^T, dir the direction of the ray through
// the mean (perspective: pv; orthographic: the forward axis). Along a ray of direction r the response peaks where
// r . Sigma_v^-1 (x - mean) = 0; for the ray through the mean that is the mean, and this plane is the tangent plane
// there of the surface of peaks (StochasticSplats' approximate_plane: gradient Sigma^-1 mean; exact for an
// orthographic camera, whose rays are parallel). The adjugate stands for the inverse (a positive factor). In pixel
// coordinates, out = (a, b, c, d): the plane along the ray of pixel (px, py) lies at 1/z (perspective) or -z
// (orthographic) = (a px + b py + c) / d, d > 0 for a positive definite Sigma_v: larger is nearer.
GBV_HD DepthPlane popfree_plane(const CameraParams& cam, const float pv[3], const float cov3[6]) {
    const float S[9] = {cov3[0], cov3[1], cov3[2], cov3[1], cov3[3], cov3[4], cov3[2], cov3[4], cov3[5]};
    const float* R = cam.R;
    float RS[9], V[9];  // V = R S R^T
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) RS[i * 3 + j] = dot3_rn(R + i * 3, 1, S + j, 3);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) V[i * 3 + j] = dot3_rn(RS + i * 3, 1, R + j * 3, 1);
    const float adj[9] = {
        minor_rn(V[4], V[8], V[5], V[7]), minor_rn(V[2], V[7], V[1], V[8]), minor_rn(V[1], V[5], V[2], V[4]),
        minor_rn(V[5], V[6], V[3], V[8]), minor_rn(V[0], V[8], V[2], V[6]), minor_rn(V[2], V[3], V[0], V[5]),
        minor_rn(V[3], V[7], V[4], V[6]), minor_rn(V[1], V[6], V[0], V[7]), minor_rn(V[0], V[4], V[1], V[3])};
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    const float dir[3] = {ortho ? 0.0f : pv[0], ortho ? 0.0f : pv[1], ortho ? 1.0f : pv[2]};
    float n[3];
    for (int i = 0; i < 3; ++i) n[i] = dot3_rn(adj + i * 3, 1, dir, 1);
    const float c = dot3_rn(n, 1, pv, 1);  // the plane n . x = c
    // the pixel's ray: view x = (px - cx) / fx, y = (py - cy) / fy, times z when perspective
    const float a = n[0] / cam.fx, b = n[1] / cam.fy;
    return {a, b, (ortho ? -c : n[2]) - mul_rn(a, cam.cx) - mul_rn(b, cam.cy), ortho ? n[2] : c};
}

// popfree_plane of one splat from its scene inputs (mean, scale, quat, filter_3d), its covariance as the stage's
// (the 3D filter included).
GBV_HD DepthPlane splat_popfree_plane(const CameraParams& cam, const SplatIn& in) {
    SplatInLanes<Lanes1> l{};
    for (int i = 0; i < 3; ++i) l.mean[i] = in.mean[i], l.scale[i] = in.scale[i];
    for (int i = 0; i < 4; ++i) l.quat[i] = in.quat[i];
    l.filter_3d = in.filter_3d;
    float pv[3], s[3], opacity = 1.0f, cov3[6];
    view_point<Lanes1>(cam, l.mean, pv);
    filter_3d_scales<Lanes1>(l, s, &opacity);
    covariance_3d<Lanes1>(l.quat, s, cov3);
    return popfree_plane(cam, pv, cov3);
}

}  // namespace gbv
