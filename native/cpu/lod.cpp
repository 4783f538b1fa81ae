// The splat hierarchy (lod.h; its cut: lod_cut.cpp). Build: Morton codes of the centres (21 bits per axis over their bounds),
// a parallel sort, then levels of 8 consecutive nodes merged bottom-up in float64: each node carries its leaves'
// mass W = sum a A, mean, covariance (the mixture's second central moment), optical mass T = sum -ln(1 - a) A and SH
// mean, so every node's moments are exactly the W-weighted moments of its leaves whatever the tree above them.
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

int team(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

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
    double w, v, t, mean[3], cov[6], radius, size, filter;  // cov: xx xy xz yy yz zz
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
    double l[3], smax = 0.0;
    for (int a = 0; a < 3; ++a) {
        l[a] = (double)s.scales[3 * i + a] * s.scales[3 * i + a];
        smax = std::max(smax, (double)s.scales[3 * i + a]);
    }
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
    m.size = 2.0 * smax;
    m.filter = s.filter ? s.filter[i] : 0.0;
    return m;
}

// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations: eigenvalues l, eigenvectors V's columns.
void eigen(const double cov[6], double l[3], double V[3][3]) {
    double A[3][3] = {{cov[0], cov[1], cov[2]}, {cov[1], cov[3], cov[4]}, {cov[2], cov[4], cov[5]}};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) V[r][c] = r == c;
    for (int sweep = 0; sweep < 32; ++sweep) {
        const double off = A[0][1] * A[0][1] + A[0][2] * A[0][2] + A[1][2] * A[1][2];
        const double diag = A[0][0] * A[0][0] + A[1][1] * A[1][1] + A[2][2] * A[2][2];
        if (off <= 1e-30 * diag || off == 0.0) break;
        for (int p = 0; p < 2; ++p)
            for (int q = p + 1; q < 3; ++q) {
                if (A[p][q] == 0.0) continue;
                const double theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q]);
                const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
                const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < 3; ++k) {  // A <- J^T A J
                    const double akp = A[k][p], akq = A[k][q];
                    A[k][p] = c * akp - s * akq;
                    A[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; ++k) {
                    const double apk = A[p][k], aqk = A[q][k];
                    A[p][k] = c * apk - s * aqk;
                    A[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; ++k) {
                    const double vkp = V[k][p], vkq = V[k][q];
                    V[k][p] = c * vkp - s * vkq;
                    V[k][q] = s * vkp + c * vkq;
                }
            }
    }
    for (int a = 0; a < 3; ++a) l[a] = std::max(A[a][a], 0.0);
    const double det = V[0][0] * (V[1][1] * V[2][2] - V[1][2] * V[2][1]) -
                       V[0][1] * (V[1][0] * V[2][2] - V[1][2] * V[2][0]) +
                       V[0][2] * (V[1][0] * V[2][1] - V[1][1] * V[2][0]);
    if (det < 0)
        for (int k = 0; k < 3; ++k) V[k][2] = -V[k][2];  // a rotation
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

// Merge children [0, count) into `out`, writing interior node i's float32 arrays. sh_of(c): child c's SH row.
template <class ShOf>
void merge(const Moments* kids, int count, ShOf sh_of, int k, OpacityRule rule, Tree& tree, int64_t i,
           Moments& out) {
    double W = 0.0, Vsum = 0.0, T = 0.0;
    for (int c = 0; c < count; ++c) W += kids[c].w, Vsum += kids[c].v, T += kids[c].t;
    auto weight = [&](int c) { return Vsum > 0 ? kids[c].v / Vsum : 1.0 / count; };  // massless leaves: equal weights
    Moments m{};
    m.w = W, m.v = Vsum, m.t = T;
    for (int c = 0; c < count; ++c)
        for (int a = 0; a < 3; ++a) m.mean[a] += weight(c) * kids[c].mean[a];
    const int pairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
    for (int c = 0; c < count; ++c) {
        const double d[3] = {kids[c].mean[0] - m.mean[0], kids[c].mean[1] - m.mean[1], kids[c].mean[2] - m.mean[2]};
        for (int e = 0; e < 6; ++e) m.cov[e] += weight(c) * (kids[c].cov[e] + d[pairs[e][0]] * d[pairs[e][1]]);
        m.radius = std::max(m.radius, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + kids[c].radius);
        m.filter += weight(c) * kids[c].filter;
    }
    double l[3], V[3][3];
    eigen(m.cov, l, V);
    const double A = area(l);
    m.size = 2.0 * std::sqrt(std::max({l[0], l[1], l[2]}));
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
    tree.size[i] = (float)m.size;
    if (!tree.filter.empty()) tree.filter[i] = (float)m.filter;
    for (int j = 0; j < 3 * k; ++j) {
        double v = 0.0;
        for (int c = 0; c < count; ++c) v += weight(c) * sh_of(c)[j];
        tree.sh[(size_t)i * 3 * k + j] = (float)v;
    }
    out = m;
}

}  // namespace

Tree build(const Splats& s, OpacityRule rule, int threads) {
    if (s.n < 1 || s.n > INT32_MAX / 2) throw std::invalid_argument("lod build: 1 to 2^30 splats");
    const int nt = team(threads);
    const int64_t n = s.n;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int64_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], (double)s.means[3 * i + a]),
                                    hi[a] = std::max(hi[a], (double)s.means[3 * i + a]);
    std::vector<std::pair<uint64_t, int32_t>> keys(n);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int64_t i = 0; i < n; ++i) {
        uint64_t code = 0;
        for (int a = 0; a < 3; ++a) {
            const double span = hi[a] - lo[a];
            const double u = span > 0 ? (s.means[3 * i + a] - lo[a]) / span : 0.0;
            code |= spread((uint64_t)std::min(u * 2097152.0, 2097151.0)) << a;
        }
        keys[i] = {code, (int32_t)i};
    }
    omp_set_num_threads(nt);
#if defined(_OPENMP) && defined(__GLIBCXX__)
    __gnu_parallel::sort(keys.begin(), keys.end());
#else
    std::sort(keys.begin(), keys.end());  // the keys are unique (index last), so the order is the same
#endif
    Tree t;
    t.order.resize(n);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int64_t i = 0; i < n; ++i) t.order[i] = keys[i].second;
    std::vector<std::pair<uint64_t, int32_t>>().swap(keys);

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

    std::vector<Moments> prev, cur;
    for (size_t l = 2; l < t.levels.size(); ++l) {
        const int64_t first = t.levels[l - 1], count = t.levels[l] - first, below = first - t.levels[l - 2];
        cur.assign(count, Moments{});
#pragma omp parallel for num_threads(nt) schedule(static, 256)
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
            merge(kids, (int)cn, [&](int c) { return rows[c]; }, k, rule, t, first - n + q, cur[q]);
        }
        std::swap(prev, cur);
    }
    return t;
}

}  // namespace gbv::lod
