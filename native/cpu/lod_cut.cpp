// The per-camera cut through the splat hierarchy (lod.h): top down over the nodes it reaches, or by its definition
// over every node when most of the tree is reached.
#include "omp_shim.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "lod.h"
#include "testing.h"

namespace gbv::lod {
namespace {

// The caller's stop, asked by every thread at most once per 4096 nodes of its loop (at(i)) or between phases
// (now()); sticky once it said true.
class Halt {
  public:
    explicit Halt(const Stop& stop) : stop_(stop) {}
    bool at(int64_t i) { return hit_.load(std::memory_order_relaxed) || ((i & 4095) == 0 && now()); }
    bool now() {
        if (!hit_.load(std::memory_order_relaxed) && stop_ && stop_()) hit_.store(true, std::memory_order_relaxed);
        return hit_.load(std::memory_order_relaxed);
    }

  private:
    const Stop& stop_;
    std::atomic<bool> hit_{false};
};

// A relative margin far above the double rounding of either form of the opening's tests (~1e-15).
constexpr double SURE = 1e-9;

// o of interior node i (its projected size against tau; see cut in lod.h). In perspective p = s / gap (s = size x
// focal, gap = |d| - radius, p infinite where gap <= 0), so with hi = tau (1 + band), s >= 0 and radius >= 0 (as
// built): p >= hi (o = 1) iff |d| hi <= s + radius hi, and p <= tau (o = 0) iff |d| tau >= s + radius tau. Both
// are decided squared, without a square root or a division, where they hold by the margin SURE and no square
// overflows (most nodes), else by the exact form. (A negative radius could
// cancel s + radius tau below its rounding, an overflowing square the margin.)
float opening(const float* means, const float* radius, const float* size, int64_t i, const View& v, double tau,
              double band) {
    double p = INFINITY;  // projected size in pixels
    if (v.orthographic) {
        p = size[i] * v.focal;
    } else {
        const double d[3] = {means[3 * i] - v.eye[0], means[3 * i + 1] - v.eye[1], means[3 * i + 2] - v.eye[2]};
        const double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double s = size[i] * v.focal, r = radius[i];
        if (tau > 0 && s >= 0 && r >= 0) {
            const double hi = tau * (1.0 + std::max(band, 0.0)), a = s + r * hi, b = s + r * tau;
            const double dh2 = dd * hi * hi, dt2 = dd * tau * tau, a2 = a * a, b2 = b * b;
            if (std::isfinite(dh2) && std::isfinite(dt2) && std::isfinite(a2) && std::isfinite(b2)) {
                if (dh2 < a2 * (1.0 - SURE)) return 1.0f;
                if (dt2 * (1.0 - SURE) > b2) return 0.0f;
            }
        }
        const double gap = std::sqrt(dd) - r;
        if (gap > 0) p = s / gap;
    }
    double o = 1.0;
    if (tau > 0) o = band > 0 ? std::clamp((p - tau) / (tau * band), 0.0, 1.0) : (p >= tau ? 1.0 : 0.0);
    return (float)o;
}

// Appends (row(i), drawn(i)) for every i in [0, len) with drawn(i) > 0, in the order of i, to c's rows and weights:
// counted per thread, then written at each thread's offset (a thread that stopped counting early, halt being sticky,
// writes nothing: never more than it counted).
template <class Drawn, class Row>
void compact(int64_t len, Drawn drawn, Row row, Cut& c, int nt, Halt& halt) {
    const int64_t at0 = (int64_t)c.rows.size();
    std::vector<int64_t> counts(nt + 1, 0);
#pragma omp parallel num_threads(nt)
    {
        const int th = omp_get_thread_num(), nth = omp_get_num_threads();
        const int64_t b = len * th / nth, e = len * (th + 1) / nth;
        int64_t local = 0;
        for (int64_t i = b; i < e && !halt.at(i); ++i) local += drawn(i) > 0.0f;
        counts[th + 1] = local;
#pragma omp barrier
#pragma omp single
        {
            for (int j = 0; j < nth; ++j) counts[j + 1] += counts[j];
            c.rows.resize(at0 + counts[nth]), c.weights.resize(at0 + counts[nth]);
        }
        int64_t at = at0 + counts[th];
        for (int64_t i = b; i < e && !halt.at(i); ++i) {
            const float d = drawn(i);
            if (d > 0.0f) c.rows[at] = row(i), c.weights[at++] = d;
        }
    }
}

// Whether splat index s is one of the n splats: the scatters by splat write only those (`order` is a permutation
// wherever it comes from gbviewer, but the cut must not write outside its array whatever it is given).
bool in_range(int32_t s, int64_t n) { return s >= 0 && s < n; }

// Whether a cut's `drawn` leaves of n come in splat order (over half of them: the stage reads long runs of
// consecutive rows) rather than in the tree's (Morton) order, which needs no sort (lod.h).
bool splat_order(int64_t drawn, int64_t n) { return drawn > n / 2; }

// The drawn leaves ascending by splat: `scatter(w)` writes every element of w (n floats): each drawn leaf's weight,
// zero elsewhere; then those over zero are compacted.
template <class Scatter>
void by_splat(int64_t n, Scatter scatter, Cut& c, int nt, Halt& halt) {
    Plane<float> w(n);
    scatter(w.data());
    compact(n, [&](int64_t i) { return w[i]; }, [](int64_t i) { return (int32_t)i; }, c, nt, halt);
}

// The cut by its definition, over every node: each interior node's o, the weights top-down level by level, each
// leaf's; what the top-down walk falls back to when most of the tree is reached.
Cut cut_flat(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
             const int32_t* order, const View& v, double tau, double band, int32_t node_base, int nt, Halt& halt) {
    const int64_t n = levels[1], m = levels[num_levels - 1] - n;
    Plane<float> open(m), weight(m);  // o and the weight reaching each interior node (every one written below)
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int64_t i = 0; i < m; ++i)
        if (!halt.at(i)) open[i] = opening(means, radius, size, i, v, tau, band);
    // Weights top-down: the root gets 1, a child its parent's weight times the parent's o.
    auto parent = [&](int l, int64_t id) { return levels[l + 1] + (id - levels[l]) / BRANCHING - n; };
    if (m > 0) weight[m - 1] = 1.0f;
    for (int l = num_levels - 3; l >= 1 && !halt.now(); --l) {
#pragma omp parallel for num_threads(nt) schedule(static)
        for (int64_t id = levels[l]; id < levels[l + 1]; ++id) {
            const int64_t p = parent(l, id);
            weight[id - n] = weight[p] * open[p];
        }
    }
    Cut c;
    if (halt.now()) return c;
    c.rows.reserve(n + m), c.weights.reserve(n + m);  // the leaves' and nodes' compactions then grow it in place
    // leaf id (Morton position; splat order[id]) is drawn at its parent's weight times o
    const auto leaf = [&](int64_t id) { return m > 0 ? weight[parent(0, id)] * open[parent(0, id)] : 1.0f; };
    int64_t drawn = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : drawn)
    for (int64_t id = 0; id < n; ++id) drawn += leaf(id) > 0.0f;
    if (splat_order(drawn, n))
        by_splat(
            n,
            [&](float* w) {
#pragma omp parallel for num_threads(nt) schedule(static)
                for (int64_t id = 0; id < n; ++id)
                    if (in_range(order[id], n)) w[order[id]] = leaf(id);
            },
            c, nt, halt);
    else
        compact(n, leaf, [&](int64_t id) { return order[id]; }, c, nt, halt);
    c.leaves = (int64_t)c.rows.size();
    if (halt.now()) return c;
    compact(
        m, [&](int64_t i) { return weight[i] * (1.0f - open[i]); }, [&](int64_t i) { return (int32_t)(node_base + i); },
        c, nt, halt);
    return c;
}

// Nodes with the weight reaching them: a level's reached interior nodes, its drawn ones, or level 1's leaves (splats).
struct Reached {
    Plane<int32_t> id;
    Plane<float> w;
    int64_t size() const { return (int64_t)id.size(); }
    void resize(int64_t k) { id.resize(k), w.resize(k); }
};

// Walked levels under this many children run on one thread (under ~1 ms: a parallel region costs more).
constexpr int64_t WALK_PARALLEL_MIN = 1 << 15;

// Level l of the walk: each reached node's o once (in `o`: the fallback's check's, or computed here when empty),
// drawn at w (1 - o), w o passed to each of its children (level 1's: leaves, as splats). Counted per thread, then
// written at each thread's offsets, so both outputs stay ascending.
void walk_level(const Reached& frontier, Plane<float>& o, int l, const float* means, const float* radius,
                const float* size, const int64_t* levels, const int32_t* order, const View& v, double tau, double band,
                int nt, Halt& halt, Reached& drawn, Reached& down) {
    const int64_t len = frontier.size(), n = levels[1];
    if (len * BRANCHING < WALK_PARALLEL_MIN) nt = 1;
    const bool known = !o.empty();
    o.resize(len);
    const auto children = [&](int64_t f) {  // [first, last) of frontier[f]'s children on level l - 1
        const int64_t first = levels[l - 1] + BRANCHING * (frontier.id[f] + n - levels[l]);
        return std::pair<int64_t, int64_t>{first, std::min(first + BRANCHING, levels[l])};
    };
    std::vector<int64_t> kept(nt + 1, 0), kids(nt + 1, 0);
#pragma omp parallel num_threads(nt)
    {
        const int th = omp_get_thread_num(), nth = omp_get_num_threads();
        const int64_t b = len * th / nth, e = len * (th + 1) / nth;
        int64_t k = 0, c = 0;
        for (int64_t f = b; f < e && !halt.at(f); ++f) {
            if (!known) o[f] = opening(means, radius, size, frontier.id[f], v, tau, band);
            const float w = frontier.w[f];
            k += w * (1.0f - o[f]) > 0.0f;
            if (w * o[f] > 0.0f) {
                const auto [first, last] = children(f);
                c += last - first;
            }
        }
        kept[th + 1] = k, kids[th + 1] = c;
#pragma omp barrier
#pragma omp single
        {
            for (int j = 0; j < nth; ++j) kept[j + 1] += kept[j], kids[j + 1] += kids[j];
            drawn.resize(kept[nth]), down.resize(kids[nth]);
        }
        int64_t at = kept[th], below = kids[th];
        for (int64_t f = b; f < e && !halt.at(f); ++f) {
            const float w = frontier.w[f], kw = w * (1.0f - o[f]), pw = w * o[f];
            if (kw > 0.0f) drawn.id[at] = frontier.id[f], drawn.w[at++] = kw;
            if (!(pw > 0.0f)) continue;
            const auto [first, last] = children(f);
            for (int64_t child = first; child < last; ++child, ++below)
                down.id[below] = l == 1 ? order[child] : (int32_t)(child - n), down.w[below] = pw;
        }
    }
}

// Top down from the root, visiting only the nodes the cut reaches (a node is reached when its parent opens, o > 0):
// the cost follows the cut, not the scene (cut_flat once most of a large level is reached and most of it opens on;
// testing's cut_flat_above 0: always). A reached node of weight w (the root 1) is drawn at w (1 - o) and passes w o
// to its children: the products the flat definition forms, so both give the same cut.
Cut cut_walk(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
             const int32_t* order, const View& v, double tau, double band, int32_t node_base, int nt, Halt& halt) {
    const int64_t n = levels[1], m = levels[num_levels - 1] - n;
    Cut c;
    if (m == 0) {  // one splat: the leaf
        c.rows.assign(n, 0);
        c.weights.assign(n, 1.0f);
        c.leaves = n;
        return c;
    }
    const int64_t flat_above = cpu::testing::cut_flat_above.load(std::memory_order_relaxed);
    if (flat_above == 0)
        return cut_flat(means, radius, size, levels, num_levels, order, v, tau, band, node_base, nt, halt);
    Reached frontier, next, leaves;  // level 1's children: leaves (splat, weight)
    frontier.resize(1);
    frontier.id[0] = (int32_t)(m - 1), frontier.w[0] = 1.0f;
    std::vector<Reached> drawn(num_levels);  // per level, ascending
    Plane<float> opens;  // the frontier's openings
    for (int l = num_levels - 2; l >= 1; --l) {  // level l's reached nodes: frontier
        // (after a stop, part of the frontier was never written: read none of it)
        if (halt.now()) return c;
        const int64_t reached = frontier.size();
        opens.clear();
        if (reached > flat_above && reached * 4 > levels[l + 1] - levels[l]) {
            // Most of a large level reached: the definition over every node costs less than walking (a walked entry
            // costs about 3 of its) once the walk would go on into most of the tree: here when over 3/4 of the
            // reached nodes open, on level 1 when their leaves (up to 8 each) would be over a third of the splats.
            opens.resize(reached);
            int64_t opened = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : opened)
            for (int64_t f = 0; f < reached; ++f) {
                opens[f] = opening(means, radius, size, frontier.id[f], v, tau, band);
                opened += frontier.w[f] * opens[f] > 0.0f;
            }
            if (l == 1 ? opened * BRANCHING * 3 > n : opened * 4 > reached * 3)
                return cut_flat(means, radius, size, levels, num_levels, order, v, tau, band, node_base, nt, halt);
        }
        walk_level(frontier, opens, l, means, radius, size, levels, order, v, tau, band, nt, halt, drawn[l],
                   l == 1 ? leaves : next);
        std::swap(frontier, next);
    }
    if (halt.now()) return c;
    int64_t total = leaves.size();  // the drawn leaves and nodes: the cut's size, allocated once
    for (int l = 1; l < num_levels; ++l) total += drawn[l].size();
    c.rows.reserve(total), c.weights.reserve(total);
    if (splat_order(leaves.size(), n)) {
        by_splat(
            n,
            [&](float* w) {
#pragma omp parallel num_threads(nt)
                {
#pragma omp for schedule(static)
                    for (int64_t i = 0; i < n; ++i) w[i] = 0.0f;
#pragma omp for schedule(static)
                    for (int64_t j = 0; j < leaves.size(); ++j)
                        if (in_range(leaves.id[j], n)) w[leaves.id[j]] = leaves.w[j];
                }
            },
            c, nt, halt);
    } else {  // in the walk's order: the tree's
        c.rows.assign(leaves.id.begin(), leaves.id.end());
        c.weights.assign(leaves.w.begin(), leaves.w.end());
    }
    c.leaves = (int64_t)c.rows.size();
    int64_t at = c.leaves;
    c.rows.resize(total), c.weights.resize(total);
    for (int l = 1; l < num_levels; ++l) {
        const Reached& d = drawn[l];
        for (int64_t j = 0; j < d.size(); ++j, ++at) c.rows[at] = node_base + d.id[j], c.weights[at] = d.w[j];
    }
    return c;
}

}  // namespace

// The cut (lod.h); `stopped` once the stop said true.
Cut cut(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
        const int32_t* order, const View& v, double tau, double band, int32_t node_base, int threads,
        const Stop& stop) {
    Halt halt(stop);
    Cut c = cut_walk(means, radius, size, levels, num_levels, order, v, tau, band, node_base, team(threads), halt);
    c.stopped = halt.now();
    return c;
}

}  // namespace gbv::lod
