// A projected splat's screen footprint (preprocess.h): eigen-decomposition of its 2D covariance, bounding radius,
// the cutoff box its mode can change pixels in, and tile rectangles. Templates over a lane type L (lanes.h).
#pragma once

#include "common.h"
#include "lanes.h"

namespace gbv {

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

}  // namespace gbv
