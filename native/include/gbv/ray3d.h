// A splat evaluated along a pixel's ray instead of as its projected 2D Gaussian: `eval3d` (3DGUT's ray maximum,
// nv-tlabs/3dgrut, gsplat docs/3dgut.md) and `stopthepop`'s per-pixel depth (r4dl/StopThePop-Rasterization,
// cuda_rasterizer/stopthepop/stopthepop_common.cuh: depthAlongRay). Shared by every backend.
//
// For the ray o + t d and the splat's precision matrix P = Sigma^-1 = A^T A (A = S^-1 R^T in camera space, the
// whitening map), the response along the ray is largest at t* = d.P(mu - o) / d.P d, where it is
// exp(-E / 2) with E = (mu-o).P(mu-o) - (d.P(mu-o))^2 / d.P d = |r x u|^2 / |u|^2, r = A(mu - o), u = A d.
// The ray is a half line: where t* < 0 its maximum is at t = 0, E = |r|^2 (the camera inside or beside the splat).
// Perspective: o = 0, d = (x - cx)/fx, (y - cy)/fy, 1); orthographic: o = ((x - cx)/fx, (y - cy)/fy, 0), d = (0, 0, 1).
// With the pixel offset (dx, dy) from the splat's screen position, w = dx a0 + dy a1 (a0 = A e_x / fx, a1 = A e_y / fy)
// and the centre ray's r and u exactly parallel, E = |c x w|^2 / |u|^2 (perspective c = A mu, orthographic
// c = A e_z): no cancellation between two large terms, however far the splat is in units of its size. t* is the
// view-space z of the maximum (d has z = 1), so the per-pixel order by t* is StopThePop's order by its distance
// along the unit view direction.
#pragma once

#include "common.h"
#include "gaussian.h"
#include "lanes.h"
#include "preprocess_stage.h"

namespace gbv {

// StopThePop's depth uses scales clamped to >= 1e-3 (computeInvCov3D, stopthepop_common.cuh).
constexpr float STOPTHEPOP_MIN_SCALE = 1e-3f;

// A splat's ray data: whitened centre c (perspective A mu, orthographic z A e_z), the whitened direction u0 of the
// ray through its screen position (perspective c / z, orthographic A e_z), and the whitened change of the ray per
// pixel in x (a0) and y (a1).
struct RaySplat {
    float c[3], u0[3], a0[3], a1[3];
    int32_t ortho;
};

GBV_HD float dot3(const float a[3], const float b[3]) {
    return mul_rn(a[0], b[0]) + mul_rn(a[1], b[1]) + mul_rn(a[2], b[2]);
}

// The ray data of a splat (mean in world space, unit (w,x,y,z) quaternion, scales; filter_3d > 0: Mip-Splatting's
// 3D filter, as the stage applies it; scales below min_scale are raised to it first). False when a scale is not
// positive or the result is not finite.
GBV_HD bool ray_splat(const CameraParams& cam, const float mean[3], const float quat[4], const float scale[3],
                      float filter_3d, float min_scale, RaySplat* out) {
    const float* W = cam.R;
    float pv[3];
    for (int i = 0; i < 3; ++i)
        pv[i] = mul_rn(W[i * 3], mean[0]) + mul_rn(W[i * 3 + 1], mean[1]) + mul_rn(W[i * 3 + 2], mean[2]) + cam.t[i];
    const float r = quat[0], x = quat[1], y = quat[2], z = quat[3];
    const float Rq[9] = {1.0f - 2.0f * (mul_rn(y, y) + mul_rn(z, z)), 2.0f * (mul_rn(x, y) - mul_rn(r, z)),
                         2.0f * (mul_rn(x, z) + mul_rn(r, y)),        2.0f * (mul_rn(x, y) + mul_rn(r, z)),
                         1.0f - 2.0f * (mul_rn(x, x) + mul_rn(z, z)), 2.0f * (mul_rn(y, z) - mul_rn(r, x)),
                         2.0f * (mul_rn(x, z) - mul_rn(r, y)),        2.0f * (mul_rn(y, z) + mul_rn(r, x)),
                         1.0f - 2.0f * (mul_rn(x, x) + mul_rn(y, y))};
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    bool ok = true;
    for (int i = 0; i < 3; ++i) {  // row i of A: the splat's axis i in camera space over its scale
        float s = scale[i] > min_scale ? scale[i] : min_scale;
        if (filter_3d > 0.0f) s = sqrtf(mul_rn(s, s) + mul_rn(filter_3d, filter_3d));
        ok = ok && s > 0.0f;
        float row[3];
        for (int k = 0; k < 3; ++k)
            row[k] = (mul_rn(W[k * 3], Rq[i]) + mul_rn(W[k * 3 + 1], Rq[3 + i]) + mul_rn(W[k * 3 + 2], Rq[6 + i])) / s;
        out->c[i] = ortho ? mul_rn(pv[2], row[2]) : dot3(row, pv);
        out->u0[i] = ortho ? row[2] : out->c[i] / pv[2];
        out->a0[i] = row[0] / cam.fx;
        out->a1[i] = row[1] / cam.fy;
        ok = ok && finitef(out->c[i]) && finitef(out->u0[i]) && finitef(out->a0[i]) && finitef(out->a1[i]);
    }
    out->ortho = ortho ? 1 : 0;
    return ok;
}

// E (the squared Mahalanobis distance of the ray's maximum over t >= 0) at the pixel offset (dx, dy) from the
// splat's screen position; *t = t*, the unclamped depth of the line's maximum (the half line's is max(t*, 0)).
GBV_HD float ray_max(const RaySplat& s, float dx, float dy, float* t) {
    float w[3], u[3], r[3];
    for (int i = 0; i < 3; ++i) {
        w[i] = mul_rn(dx, s.a0[i]) + mul_rn(dy, s.a1[i]);
        u[i] = s.ortho ? s.u0[i] : s.u0[i] + w[i];
        r[i] = s.ortho ? s.c[i] - w[i] : s.c[i];
    }
    const float uu = dot3(u, u);
    *t = dot3(r, u) / uu;
    if (!(*t > 0.0f)) return dot3(r, r);
    const float* c = s.ortho ? s.u0 : s.c;
    const float n[3] = {mul_rn(c[1], w[2]) - mul_rn(c[2], w[1]), mul_rn(c[2], w[0]) - mul_rn(c[0], w[2]),
                        mul_rn(c[0], w[1]) - mul_rn(c[1], w[0])};
    return dot3(n, n) / uu;
}

// One splat's fragment at a pixel in the per-pixel sorted modes: its alpha and its depth, or false when it adds
// nothing there. eval3d: alpha = min(0.99, o exp(-E/2)) at the ray maximum, depth max(t*, 0); stopthepop: the 2D
// alpha of 3DGS (the splat's conic at the pixel, as the published kernel computes it) with depth t*, dropped where
// t* < 0 (hierarchical_render.cuh: `depth < 0.0f` is skipped). Both skip alpha < 1/255, before the exp where the
// exponent is below log_min_alpha = ln((1/255) / o).
GBV_HD bool sorted_fragment(Mode mode, const Splat2D& s, const RaySplat& ray, float px, float py, float* alpha,
                            float* depth) {
    const float dx = px - s.xy.x, dy = py - s.xy.y;
    float t;
    const float E = ray_max(ray, dx, dy, &t);
    float power;
    if (mode == STOPTHEPOP) {
        if (!(t >= 0.0f)) return false;
        power = gaussian_power<Lanes1>(s, s.xy.x - px, s.xy.y - py);
        *depth = t;
    } else {
        power = -0.5f * E;
        *depth = t > 0.0f ? t : 0.0f;
    }
    if (!(power <= 0.0f) || power < s.log_min_alpha) return false;
    const float a = s.opacity * expf(power);
    *alpha = a < MAX_ALPHA ? a : MAX_ALPHA;
    return *alpha >= MIN_ALPHA_3DGS;
}

// a * b in double, never fused with a following add (mul_rn's rule for the footprint's double arithmetic: nvcc fuses
// by default, the host builds with -ffp-contract=off), so every backend culls the same tiles.
GBV_HD double dmul_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
    return __dmul_rn(a, b);
#else
    return a * b;
#endif
}

// The pixel offsets from the splat's screen position where the half line's E can be <= r2 = -2 log_min_alpha (with
// margins for the float evaluation), as the box [x0, x1] x [y0, y1] in box[0..4). Returns 0: no pixel, 1: the box,
// 2: unbounded (the camera inside the grown ellipsoid E <= r2, or its cone of rays reaching past the image plane's
// horizon). The rays that meet the ellipsoid |A(p - mu)|^2 <= r2 have u^T G u <= 0 with
// G = (|c|^2 - r2) I - c c^T (perspective; u = B (dx, dy, 1), B = [a0 a1 u0]); orthographic rays have E = |u0 x w|^2 /
// |u0|^2, a quadratic form in (dx, dy). Computed in double.
GBV_HD int ray_footprint(const RaySplat& s, float log_min_alpha, double box[4]) {
    auto d3 = [](const double* x, const double* y) {
        return dmul_rn(x[0], y[0]) + dmul_rn(x[1], y[1]) + dmul_rn(x[2], y[2]);
    };
    const double a0[3] = {s.a0[0], s.a0[1], s.a0[2]}, a1[3] = {s.a1[0], s.a1[1], s.a1[2]};
    const double u0[3] = {s.u0[0], s.u0[1], s.u0[2]}, c[3] = {s.c[0], s.c[1], s.c[2]};
    const double cc = d3(c, c);
    const double r0 = -2.0 * (double)log_min_alpha;
    if (!(r0 >= 0.0)) return 0;
    // E's float error: a few ulp relative, and a few ulp of |c| |w| absolute in sqrt(E)
    const double rad = dmul_rn(sqrt(r0), 1.0 + 1e-4) + dmul_rn(1e-6, sqrt(cc)) + 1e-4;
    const double r2 = rad * rad;
    double K00, K01, K11, K02 = 0.0, K12 = 0.0, K22 = -r2;  // the region (dx, dy, 1) K (dx, dy, 1)^T <= 0
    if (s.ortho) {  // E = |w|^2 - (w.n)^2 with n = u0 / |u0|
        const double nn = d3(u0, u0);
        if (!(nn > 0.0)) return 2;
        const double p0 = d3(a0, u0), p1 = d3(a1, u0);
        K00 = d3(a0, a0) - dmul_rn(p0, p0) / nn;
        K01 = d3(a0, a1) - dmul_rn(p0, p1) / nn;
        K11 = d3(a1, a1) - dmul_rn(p1, p1) / nn;
    } else {
        const double g = cc - r2;
        if (!(g > 0.0)) return 2;  // the camera inside
        const double* B[3] = {a0, a1, u0};
        double K[3][3];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) K[i][j] = dmul_rn(g, d3(B[i], B[j])) - dmul_rn(d3(B[i], c), d3(B[j], c));
        K00 = K[0][0];
        K01 = K[0][1];
        K11 = K[1][1];
        K02 = K[0][2];
        K12 = K[1][2];
        K22 = K[2][2];
    }
    const double det = dmul_rn(K00, K11) - dmul_rn(K01, K01);
    if (!(K00 > 0.0) || !(det > 0.0)) return 2;
    const double i00 = K11 / det, i01 = -K01 / det, i11 = K00 / det;  // K2^-1
    const double cx = -(dmul_rn(i00, K02) + dmul_rn(i01, K12)), cy = -(dmul_rn(i01, K02) + dmul_rn(i11, K12));
    const double qmin = K22 + dmul_rn(K02, cx) + dmul_rn(K12, cy);
    if (!(qmin <= 0.0)) return qmin > 0.0 ? 0 : 2;
    const double hx = sqrt(-qmin * i00), hy = sqrt(-qmin * i11);
    if (!finitef((float)hx) || !finitef((float)hy) || !finitef((float)cx) || !finitef((float)cy)) return 2;
    const double pad = 0.01 + dmul_rn(1e-6, fabs(cx) + fabs(cy) + hx + hy);
    box[0] = cx - hx - pad;
    box[1] = cx + hx + pad;
    box[2] = cy - hy - pad;
    box[3] = cy + hy + pad;
    return 1;
}

// The tiles whose pixel centres may lie in the box of pixel offsets `box` about xy (ray_footprint's `kind` and box),
// widened by the rounding of the offset px - xy; pixel i's centre is i + 0.5, in tile floor(i / TILE).
GBV_HD TileRect footprint_tiles(Vec2 xy, int kind, const double box[4], int gx, int gy) {
    if (kind == 2) return {0, 0, gx, gy};
    if (kind == 0) return {0, 0, 0, 0};
    const double slack = dmul_rn(1e-6, fabs((double)xy.x) + fabs((double)xy.y));
    const double t[4] = {floor((xy.x + box[0] - slack - 0.5) / TILE), floor((xy.y + box[2] - slack - 0.5) / TILE),
                         floor((xy.x + box[1] + slack - 0.5) / TILE) + 1,
                         floor((xy.y + box[3] + slack - 0.5) / TILE) + 1};
    const double g[4] = {(double)gx, (double)gy, (double)gx, (double)gy};
    int r[4];
    for (int k = 0; k < 4; ++k) r[k] = (int)fmin(fmax(t[k], 0.0), g[k]);
    return {r[0], r[1], r[2], r[3]};
}

// A per-pixel sorted mode's finish of one splat from its stage (mean, scale, quat and filter_3d of `in` are read):
// its ray data; for eval3d also its splat (the stage's position, depth, opacity and colour: no 2D filter, the
// conic unused) and tile rectangle (ray_footprint), for stopthepop the scalar finish's splat and rectangle are kept
// (its depth uses scales >= STOPTHEPOP_MIN_SCALE). False when the splat is dropped: opacity below 1/255 or no tile
// (eval3d), degenerate ray data (both).
GBV_HD bool finish_ray_splat(const SplatIn& in, const StageSplat& st, const CameraParams& cam, Mode mode, int gx,
                             int gy, Splat2D* out, TileRect* rect, RaySplat* ray) {
    const bool ok =
        ray_splat(cam, in.mean, in.quat, in.scale, in.filter_3d, mode == STOPTHEPOP ? STOPTHEPOP_MIN_SCALE : 0.0f, ray);
    if (mode != EVAL3D) return ok;
    *out = Splat2D{};
    out->xy = {st.xy[0], st.xy[1]};
    out->depth = st.depth;
    out->opacity = st.opacity;
    for (int c = 0; c < 3; ++c) out->color[c] = st.color[c];
    out->log_min_alpha = logf(MIN_ALPHA_3DGS / st.opacity);
    out->cell = -1;
    double box[4] = {0, 0, 0, 0};
    const int kind = ok && st.opacity >= MIN_ALPHA_3DGS ? ray_footprint(*ray, out->log_min_alpha, box) : 0;
    *rect = footprint_tiles(out->xy, kind, box, gx, gy);
    return rect->x1 > rect->x0 && rect->y1 > rect->y0;
}

}  // namespace gbv
