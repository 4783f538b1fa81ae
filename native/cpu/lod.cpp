// The splat hierarchy (lod.h; its cut: lod_cut.cpp). Build: Morton codes of the centres (21 bits per axis over
// their bounds), bucketed by their top bits and sorted per bucket, then levels of 8 consecutive nodes merged
// bottom-up in float64: each node carries its leaves' mass W = sum a A, mean, covariance (the mixture's second
// central moment), optical mass T = sum -ln(1 - a) A and SH mean, so every node's moments are exactly the
// W-weighted moments of its leaves whatever the tree above them.
#include "lod.h"

#include "omp_shim.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#if defined(_OPENMP) && defined(__GLIBCXX__)
#include <parallel/algorithm>  // libstdc++'s parallel sort (OpenMP)
#endif

namespace gbv::lod {
namespace {

constexpr double PI = 3.14159265358979323846;
constexpr double MAX_ALPHA = 1.0 - 1e-7;  // a leaf's optical depth is finite
constexpr int MAX_K = 16;  // SH coefficients per channel (degree 3)

// Spread the low 21 bits of v to every third bit.
uint64_t spread(uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
}

// A node's float64 summary while the levels are merged: mass w, averaging weight v (w, or the opacity sum for
// OPACITY_WEIGHTS), optical mass t.
struct Moments {
    double w, v, t, mean[3], cov[6], radius, filter;  // cov: xx xy xz yy yz zz
};

// Mean of the three principal cross-section areas of an ellipsoid with semi-axes sqrt(l).
double area(const double l[3]) {
    const double a = std::sqrt(std::max(l[0], 0.0)), b = std::sqrt(std::max(l[1], 0.0)),
                 c = std::sqrt(std::max(l[2], 0.0));
    return PI / 3.0 * (a * b + b * c + a * c);
}

Moments leaf(const Splats& s, int64_t i, OpacityRule rule) {
    const float* q = s.quats + 4 * i;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    double l[3];
    for (int a = 0; a < 3; ++a) l[a] = (double)s.scales[3 * i + a] * s.scales[3 * i + a];
    Moments m{};
    const int pairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
    for (int e = 0; e < 6; ++e) {
        double v = 0.0;
        for (int a = 0; a < 3; ++a) v += R[pairs[e][0]][a] * l[a] * R[pairs[e][1]][a];
        m.cov[e] = v;
    }
    const double alpha = std::min((double)s.opacities[i], MAX_ALPHA), A = area(l);
    m.w = alpha * A;
    m.v = rule == OPACITY_WEIGHTS ? alpha : m.w;
    m.t = -std::log1p(-alpha) * A;
    for (int a = 0; a < 3; ++a) m.mean[a] = s.means[3 * i + a];
    m.radius = 0.0;
    m.filter = s.filter ? s.filter[i] : 0.0;
    return m;
}

double dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

void cross(const double a[3], const double b[3], double out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1], out[1] = a[2] * b[0] - a[0] * b[2], out[2] = a[0] * b[1] - a[1] * b[0];
}

// A unit eigenvector of symmetric B (rows b) for its eigenvalue e of multiplicity 1: the longest cross product of
// two rows of B - e I.
void vector_of(const double b[3][3], double e, double v[3]) {
    const double r[3][3] = {
        {b[0][0] - e, b[0][1], b[0][2]}, {b[1][0], b[1][1] - e, b[1][2]}, {b[2][0], b[2][1], b[2][2] - e}};
    double c[3][3], best = -1.0;
    cross(r[0], r[1], c[0]), cross(r[0], r[2], c[1]), cross(r[1], r[2], c[2]);
    for (int i = 0; i < 3; ++i)
        if (const double d = dot(c[i], c[i]); d > best) best = d, v[0] = c[i][0], v[1] = c[i][1], v[2] = c[i][2];
    const double inv = best > 0 ? 1.0 / std::sqrt(best) : 0.0;
    for (int i = 0; i < 3; ++i) v[i] *= inv;
    if (inv == 0.0) v[0] = 1.0;  // only a rounding of a multiple of the identity has no such product
}

// The other two eigenpairs of symmetric B, given its unit eigenvector w: B restricted to w's orthogonal complement
// (basis u, x) is the symmetric 2x2 [[a, f], [f, c]], diagonalised exactly by one Jacobi rotation. e[0] with v[0],
// e[1] with v[1].
void plane_pairs(const double b[3][3], const double w[3], double e[2], double v[2][3]) {
    double u[3], x[3];
    if (std::fabs(w[0]) > std::fabs(w[1])) {
        const double inv = 1.0 / std::sqrt(w[0] * w[0] + w[2] * w[2]);
        u[0] = -w[2] * inv, u[1] = 0.0, u[2] = w[0] * inv;
    } else {
        const double inv = 1.0 / std::sqrt(w[1] * w[1] + w[2] * w[2]);
        u[0] = 0.0, u[1] = w[2] * inv, u[2] = -w[1] * inv;
    }
    cross(w, u, x);
    double bu[3], bx[3];
    for (int i = 0; i < 3; ++i) bu[i] = dot(b[i], u), bx[i] = dot(b[i], x);
    const double a = dot(u, bu), f = dot(u, bx), c = dot(x, bx);
    double t = 0.0;  // tan of the rotation
    if (f != 0.0) {
        const double theta = (c - a) / (2.0 * f);
        t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
    }
    const double cs = 1.0 / std::sqrt(t * t + 1.0), sn = t * cs;
    e[0] = a - t * f, e[1] = c + t * f;
    for (int i = 0; i < 3; ++i) v[0][i] = cs * u[i] - sn * x[i], v[1][i] = sn * u[i] + cs * x[i];
}

// Eigen-decomposition of a symmetric 3x3 matrix (after D. Eberly, "A Robust Eigensolver for 3x3 Symmetric
// Matrices", 2014): the eigenvalues of the scaled matrix by the trigonometric solution of its shifted characteristic
// cubic pick the one farthest from the others, whose vector comes from cross products of rows of B - e I; its value
// is then its Rayleigh quotient and the other two pairs those of B in its orthogonal complement (exact: a needle's
// or a disc's small eigenvalues keep their relative precision, where the cubic's roots carry an absolute error of
// about 1e-8 of the largest). l unordered, V's columns the orthonormal vectors, det V = +1.
void eigen(const double cov[6], double l[3], double V[3][3]) {
    double scale = 0.0;
    for (int e = 0; e < 6; ++e) scale = std::max(scale, std::fabs(cov[e]));
    double b[3][3] = {};
    if (scale > 0.0)
        b[0][0] = cov[0] / scale, b[0][1] = b[1][0] = cov[1] / scale, b[0][2] = b[2][0] = cov[2] / scale,
        b[1][1] = cov[3] / scale, b[1][2] = b[2][1] = cov[4] / scale, b[2][2] = cov[5] / scale;
    const double n = b[0][1] * b[0][1] + b[0][2] * b[0][2] + b[1][2] * b[1][2];
    if (n == 0.0) {  // diagonal (at this precision)
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) V[r][c] = r == c;
        l[0] = std::max(cov[0], 0.0), l[1] = std::max(cov[3], 0.0), l[2] = std::max(cov[5], 0.0);
        return;
    }
    const double q = (b[0][0] + b[1][1] + b[2][2]) / 3.0;
    const double c00 = b[0][0] - q, c11 = b[1][1] - q, c22 = b[2][2] - q;
    const double p = std::sqrt((c00 * c00 + c11 * c11 + c22 * c22 + 2.0 * n) / 6.0);
    const double b01 = b[0][1] / p, b02 = b[0][2] / p, b12 = b[1][2] / p, d00 = c00 / p, d11 = c11 / p, d22 = c22 / p;
    const double half = std::clamp(
        0.5 * (d00 * (d11 * d22 - b12 * b12) - b01 * (b01 * d22 - b12 * b02) + b02 * (b01 * b12 - d11 * b02)), -1.0,
        1.0);
    const double angle = std::acos(half) / 3.0;
    // the largest root when it is the farthest from the middle one (half >= 0), else the smallest
    const double root = q + p * 2.0 * std::cos(half >= 0 ? angle : angle + 2.0 * PI / 3.0);
    double v[3][3], e[3], bw[3];
    vector_of(b, root, v[0]);
    for (int i = 0; i < 3; ++i) bw[i] = dot(b[i], v[0]);
    e[0] = dot(v[0], bw);
    plane_pairs(b, v[0], e + 1, v + 1);
    double vx[3];
    cross(v[1], v[2], vx);
    if (dot(v[0], vx) < 0)
        for (int i = 0; i < 3; ++i) v[2][i] = -v[2][i];  // a rotation
    for (int j = 0; j < 3; ++j) {
        l[j] = std::max(e[j] * scale, 0.0);
        for (int i = 0; i < 3; ++i) V[i][j] = v[j][i];
    }
}

// Unit quaternion (w,x,y,z) of a rotation matrix (Shepperd).
void quaternion(const double R[3][3], float q[4]) {
    const double tr = R[0][0] + R[1][1] + R[2][2];
    double w, x, y, z;
    if (tr > 0) {
        const double s = 2.0 * std::sqrt(tr + 1.0);
        w = 0.25 * s, x = (R[2][1] - R[1][2]) / s, y = (R[0][2] - R[2][0]) / s, z = (R[1][0] - R[0][1]) / s;
    } else if (R[0][0] > R[1][1] && R[0][0] > R[2][2]) {
        const double s = 2.0 * std::sqrt(1.0 + R[0][0] - R[1][1] - R[2][2]);
        w = (R[2][1] - R[1][2]) / s, x = 0.25 * s, y = (R[0][1] + R[1][0]) / s, z = (R[0][2] + R[2][0]) / s;
    } else if (R[1][1] > R[2][2]) {
        const double s = 2.0 * std::sqrt(1.0 + R[1][1] - R[0][0] - R[2][2]);
        w = (R[0][2] - R[2][0]) / s, x = (R[0][1] + R[1][0]) / s, y = 0.25 * s, z = (R[1][2] + R[2][1]) / s;
    } else {
        const double s = 2.0 * std::sqrt(1.0 + R[2][2] - R[0][0] - R[1][1]);
        w = (R[1][0] - R[0][1]) / s, x = (R[0][2] + R[2][0]) / s, y = (R[1][2] + R[2][1]) / s, z = 0.25 * s;
    }
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    q[0] = (float)(w / n), q[1] = (float)(x / n), q[2] = (float)(y / n), q[3] = (float)(z / n);
}

// Merge children [0, count) into `out`, writing interior node i's float32 arrays; rows[c]: child c's SH row.
void merge(const Moments* kids, int count, const float* const* rows, int k, OpacityRule rule, Tree& tree, int64_t i,
           Moments& out) {
    double W = 0.0, Vsum = 0.0, T = 0.0, wt[BRANCHING];
    for (int c = 0; c < count; ++c) W += kids[c].w, Vsum += kids[c].v, T += kids[c].t;
    for (int c = 0; c < count; ++c) wt[c] = Vsum > 0 ? kids[c].v / Vsum : 1.0 / count;  // massless leaves: equal
    Moments m{};
    m.w = W, m.v = Vsum, m.t = T;
    for (int c = 0; c < count; ++c)
        for (int a = 0; a < 3; ++a) m.mean[a] += wt[c] * kids[c].mean[a];
    const int pairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
    for (int c = 0; c < count; ++c) {
        const double d[3] = {kids[c].mean[0] - m.mean[0], kids[c].mean[1] - m.mean[1], kids[c].mean[2] - m.mean[2]};
        for (int e = 0; e < 6; ++e) m.cov[e] += wt[c] * (kids[c].cov[e] + d[pairs[e][0]] * d[pairs[e][1]]);
        m.radius = std::max(m.radius, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + kids[c].radius);
        m.filter += wt[c] * kids[c].filter;
    }
    double l[3], V[3][3];
    eigen(m.cov, l, V);
    const double A = area(l);
    double alpha = 0.0;
    if (A > 0)
        alpha = rule != SUM ? -std::expm1(-T / A) : std::min(1.0, W / A);
    else
        alpha = W > 0 || T > 0 ? 1.0 : 0.0;
    for (int a = 0; a < 3; ++a) {
        tree.means[3 * i + a] = (float)m.mean[a];
        tree.scales[3 * i + a] = (float)std::sqrt(l[a]);
    }
    quaternion(V, &tree.quats[4 * i]);
    tree.opacities[i] = (float)alpha;
    tree.radius[i] = (float)m.radius;
    tree.size[i] = (float)(2.0 * std::sqrt(std::max({l[0], l[1], l[2]})));
    if (!tree.filter.empty()) tree.filter[i] = (float)m.filter;
    double sh[3 * MAX_K] = {};
    for (int c = 0; c < count; ++c)
        for (int j = 0; j < 3 * k; ++j) sh[j] += wt[c] * rows[c][j];
    for (int j = 0; j < 3 * k; ++j) tree.sh[(size_t)i * 3 * k + j] = (float)sh[j];
    out = m;
}

// The splats' Morton order (21 bits per axis over the centres' bounds; ties by index): a counting pass on the codes'
// top 16 bits (stable, so every bucket is in index order), then each bucket sorted: the few large ones one after
// another with every thread, the rest in parallel. The same order as one sort of the (code, index) pairs.
Plane<int32_t> morton_order(const Splats& s, int nt) {
    const int64_t n = s.n;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
#pragma omp parallel for num_threads(nt) schedule(static) reduction(min : lo[ : 3]) reduction(max : hi[ : 3])
    for (int64_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a)
            lo[a] = std::min(lo[a], (double)s.means[3 * i + a]), hi[a] = std::max(hi[a], (double)s.means[3 * i + a]);
    const auto code = [&](int64_t i) {
        uint64_t c = 0;
        for (int a = 0; a < 3; ++a) {
            const double span = hi[a] - lo[a];
            const double u = span > 0 ? (s.means[3 * i + a] - lo[a]) / span : 0.0;
            c |= spread((uint64_t)std::min(u * 2097152.0, 2097151.0)) << a;
        }
        return c;
    };
    constexpr int TOP = 16, SHIFT = 63 - TOP;
    constexpr int64_t BUCKETS = int64_t(1) << TOP;
    struct Key {  // trivial (std::pair's constructor would zero-fill the Plane): the code, then the index
        uint64_t code;
        int32_t index;
        bool operator<(const Key& o) const { return code < o.code || (code == o.code && index < o.index); }
    };
    Plane<Key> keys(n);
    Plane<uint64_t> codes(n);
    std::vector<int64_t> at((size_t)nt * BUCKETS, 0), start(BUCKETS + 1, 0);
#pragma omp parallel num_threads(nt)
    {
        const int t = omp_get_thread_num(), nth = omp_get_num_threads();
        const int64_t b = n * t / nth, e = n * (t + 1) / nth;
        int64_t* mine = &at[(size_t)t * BUCKETS];
        for (int64_t i = b; i < e; ++i) codes[i] = code(i);
        for (int64_t i = b; i < e; ++i) ++mine[codes[i] >> SHIFT];
#pragma omp barrier
#pragma omp single
        {
            int64_t sum = 0;
            for (int64_t k = 0; k < BUCKETS; ++k) {
                start[k] = sum;
                for (int u = 0; u < nth; ++u) {
                    const int64_t count = at[(size_t)u * BUCKETS + k];
                    at[(size_t)u * BUCKETS + k] = sum, sum += count;
                }
            }
            start[BUCKETS] = sum;
        }
        for (int64_t i = b; i < e; ++i) keys[mine[codes[i] >> SHIFT]++] = {codes[i], (int32_t)i};
    }
    const int64_t big = std::max<int64_t>(n / (4 * nt), 1 << 15);
    for (int64_t k = 0; k < BUCKETS; ++k)
        if (start[k + 1] - start[k] > big) {
            omp_set_num_threads(nt);
#if defined(_OPENMP) && defined(__GLIBCXX__)
            __gnu_parallel::sort(keys.begin() + start[k], keys.begin() + start[k + 1]);
#else
            std::sort(keys.begin() + start[k], keys.begin() + start[k + 1]);
#endif
        }
    Plane<int32_t> order(n);
#pragma omp parallel for num_threads(nt) schedule(dynamic, 64)
    for (int64_t k = 0; k < BUCKETS; ++k) {
        if (start[k + 1] - start[k] <= big) std::sort(keys.begin() + start[k], keys.begin() + start[k + 1]);
        for (int64_t i = start[k]; i < start[k + 1]; ++i) order[i] = keys[i].index;
    }
    return order;
}

}  // namespace

Tree build(const Splats& s, OpacityRule rule, int threads) {
    if (s.n < 1 || s.n > INT32_MAX / 2) throw std::invalid_argument("lod build: 1 to 2^30 splats");
    if (s.k < 1 || s.k > MAX_K) throw std::invalid_argument("lod build: 1 to 16 SH coefficients per channel");
    const int nt = team(threads);
    const int64_t n = s.n;
    Tree t;
    t.order = morton_order(s, nt);

    t.levels = {0, n};
    while (t.levels.back() - t.levels[t.levels.size() - 2] > 1) {
        const int64_t below = t.levels.back() - t.levels[t.levels.size() - 2];
        t.levels.push_back(t.levels.back() + (below + BRANCHING - 1) / BRANCHING);
    }
    const int64_t m = t.levels.back() - n;
    const int k = s.k;
    t.means.resize(3 * m), t.scales.resize(3 * m), t.quats.resize(4 * m), t.opacities.resize(m);
    t.sh.resize((size_t)m * 3 * k), t.radius.resize(m), t.size.resize(m);
    if (s.filter) t.filter.resize(m);

    Plane<Moments> prev, cur;
    for (size_t l = 2; l < t.levels.size(); ++l) {
        const int64_t first = t.levels[l - 1], count = t.levels[l] - first, below = first - t.levels[l - 2];
        cur.resize(count);
        // one contiguous part of the level per thread: each sweeps its own stretch of the Morton order (faster than
        // blocks of nodes handed out in turn; bench/RESULTS.md)
#pragma omp parallel for num_threads(nt) schedule(static)
        for (int64_t q = 0; q < count; ++q) {
            const int64_t c0 = q * BRANCHING, cn = std::min<int64_t>(BRANCHING, below - c0);
            Moments kids[BRANCHING];
            const float* rows[BRANCHING];
            for (int c = 0; c < cn; ++c) {
                if (l == 2) {
                    const int32_t splat = t.order[c0 + c];
                    kids[c] = leaf(s, splat, rule);
                    rows[c] = s.sh + (size_t)splat * 3 * k;
                } else {
                    kids[c] = prev[c0 + c];
                    rows[c] = &t.sh[(size_t)(t.levels[l - 2] - n + c0 + c) * 3 * k];
                }
            }
            merge(kids, (int)cn, rows, k, rule, t, first - n + q, cur[q]);
        }
        std::swap(prev, cur);
    }
    return t;
}

}  // namespace gbv::lod
