// Host check of gaussian_blending_bounds (native/cpu/blend_tile.h), built and run by test_gb_bounds.py: on random
// splats (isotropic to needle-thin, any angle, opacity up to 1 and just above 1/256) and random windows placed
// around them, every window whose state blend_gaussian changes, and every window whose float64 mean alpha (or,
// outside [0.1, 1e6] sigma, centre alpha) reaches 1/256, has its centre inside the bounds grown by the window's
// half perimeter. Prints "ok <windows> <taken> <taken near the edge> <splats with a tighter box than the radius>".
#include <cmath>
#include <cstdio>
#include <random>

#include "blend_tile.h"
#include "gbv/footprint.h"

using namespace gbv;

namespace {

// A Splat2D as preprocess leaves it for gaussian_blending, from its screen covariance (a, b, c) and opacity.
bool make_splat(float x, float y, float a, float b, float c, float o, Splat2D& s) {
    const float det = a * c - b * b;
    if (!(det > 0.0f)) return false;
    s = Splat2D{};
    s.xy = {x, y};
    s.depth = 1.0f;
    s.opacity = o;
    s.conic[0] = c / det;
    s.conic[1] = -b / det;
    s.conic[2] = a / det;
    float v1[2];
    eigen_2d<Lanes1>(a, b, c, det, &s.sigma1, &s.sigma2, v1);
    s.v1 = {v1[0], v1[1]};
    s.inv_sigma1 = 1.0f / s.sigma1;
    s.inv_sigma2 = 1.0f / s.sigma2;
    s.radius = splat_radius<Lanes1>(a, c, det, RADIUS_SIGMAS_GB);
    s.log_min_alpha = logf(MIN_ALPHA_GB / o);
    s.cell = -1;
    return std::isfinite(s.inv_sigma2) && std::isfinite(s.log_min_alpha);
}

// Mean of exp(-t^2/2) over [c - h, c + h] (float64).
double side_mean(double c, double h) {
    const double k = std::sqrt(M_PI / 2.0) / (2.0 * h);
    return k * (std::erf((c + h) / std::sqrt(2.0)) - std::erf((c - h) / std::sqrt(2.0)));
}

// The float64 alpha the window takes from the splat (blend_gaussian's definition, exact arithmetic).
double alpha64(const Splat2D& s, double cx, double cy, double w, double h) {
    const double dx = cx - s.xy.x, dy = cy - s.xy.y;
    const double u = dx * s.v1.x + dy * s.v1.y, v = -dx * s.v1.y + dy * s.v1.x;
    const bool aligned = std::fabs(s.v1.x) > std::fabs(s.v1.y);
    const double lu = aligned ? w : h, lv = aligned ? h : w;
    const double s1 = s.sigma1, s2 = s.sigma2;
    const double su = lu / s1, sv = lv / s2;
    if (su < GB_MIN_UV_DIFF || sv < GB_MIN_UV_DIFF || su > GB_MAX_UV_DIFF || sv > GB_MAX_UV_DIFF)
        return s.opacity * std::exp(-0.5 * ((u / s1) * (u / s1) + (v / s2) * (v / s2)));
    return s.opacity * side_mean(u / s1, 0.5 * su) * side_mean(v / s2, 0.5 * sv);
}

bool inside(const SplatBounds& b, double cx, double cy, double reach) {
    return cx >= b.x0 - reach && cx <= b.x1 + reach && cy >= b.y0 - reach && cy <= b.y1 + reach;
}

}  // namespace

int main() {
    std::mt19937_64 rng(2311);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    long windows = 0, taken = 0, edge = 0, tighter = 0, failures = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        const double s1 = std::exp(std::log(0.05) + U(rng) * std::log(300.0 / 0.05));
        const double kappa = U(rng) < 0.3 ? 1.0 + U(rng) * 0.01 : std::exp(U(rng) * std::log(3000.0));
        const double s2 = std::max(s1 / kappa, 2e-3), th = U(rng) * M_PI;
        const double ct = std::cos(th), st = std::sin(th);
        const float a = (float)(s1 * s1 * ct * ct + s2 * s2 * st * st),
                    c = (float)(s1 * s1 * st * st + s2 * s2 * ct * ct);
        const float b = (float)((s1 * s1 - s2 * s2) * ct * st);
        const double pick = U(rng);
        const float o = pick < 0.3   ? 1.0f
                        : pick < 0.6 ? (float)(MIN_ALPHA_GB * (1.0 + std::pow(10.0, -6.0 * U(rng))))
                                     : (float)(MIN_ALPHA_GB + U(rng) * (1.0 - MIN_ALPHA_GB));
        Splat2D s;
        if (!make_splat((float)(U(rng) * 2000.0), (float)(U(rng) * 2000.0), a, b, c, o, s)) continue;
        const SplatBounds bd = gaussian_blending_bounds(s);
        if (bd.x1 - bd.x0 < 2.0f * s.radius - 0.5f || bd.y1 - bd.y0 < 2.0f * s.radius - 0.5f) ++tighter;
        for (int k = 0; k < 500; ++k) {
            const bool pixel = U(rng) < 0.3;
            const double w = pixel ? 1.0 : std::exp(std::log(0.03) + U(rng) * std::log(30.0 / 0.03));
            const double h = pixel ? 1.0 : std::exp(std::log(0.03) + U(rng) * std::log(30.0 / 0.03));
            const double reach = 0.5 * (w + h);
            // centres around the box (or the radius square when the box is empty), a fifth of them near its edge
            const double hx = std::isfinite(bd.x1 - bd.x0) && bd.x1 > bd.x0 ? 0.5 * (bd.x1 - bd.x0) : s.radius;
            const double hy = std::isfinite(bd.y1 - bd.y0) && bd.y1 > bd.y0 ? 0.5 * (bd.y1 - bd.y0) : s.radius;
            double fx = 2.4 * U(rng) - 1.2, fy = 2.4 * U(rng) - 1.2;
            if (U(rng) < 0.2) (U(rng) < 0.5 ? fx : fy) = (U(rng) < 0.5 ? -1.0 : 1.0) * (0.97 + 0.06 * U(rng));
            const float cx = (float)(s.xy.x + fx * (hx + reach)), cy = (float)(s.xy.y + fy * (hy + reach));
            WindowState<Lanes1> win = {(float)(1e-4 + U(rng)), cx, cy, (float)w, (float)h, {0.0f, 0.0f, 0.0f}};
            const WindowState<Lanes1> before = win;
            bool took = false;
            blend_gaussian<Lanes1>(s, true, win, &took);
            const bool changed = took || win.T != before.T || win.C[0] != 0.0f || win.x != before.x ||
                                 win.y != before.y || win.w != before.w || win.h != before.h;
            const bool visible64 = alpha64(s, cx, cy, (float)w, (float)h) >= MIN_ALPHA_GB;
            ++windows;
            if (!changed && !visible64) continue;
            ++taken;
            if (std::fabs(fx) > 0.9 || std::fabs(fy) > 0.9) ++edge;
            if (!inside(bd, cx, cy, reach)) {
                if (++failures <= 10)
                    printf("outside: sigma %g %g v1 (%g %g) o %.9g window (%.9g %.9g) %g x %g changed %d alpha64 %d\n",
                           s.sigma1, s.sigma2, s.v1.x, s.v1.y, s.opacity, cx, cy, w, h, changed, visible64);
            }
        }
    }
    if (failures) {
        printf("FAIL %ld windows outside the bounds\n", failures);
        return 1;
    }
    printf("ok %ld %ld %ld %ld\n", windows, taken, edge, tighter);
    return 0;
}
