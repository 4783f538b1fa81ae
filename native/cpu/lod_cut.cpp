// The per-camera cut through the splat hierarchy (lod.h): top down over the nodes it reaches, or by its definition
// over every node when most of the tree is reached.
#include "omp_shim.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <utility>
#include <vector>

#include "lod.h"
#include "testing.h"

namespace gbv::lod {
namespace {

int team(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

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

// o of interior node i (its projected size against tau; see cut in lod.h).
float opening(const float* means, const float* radius, const float* size, int64_t i, const View& v, double tau,
              double band) {
    double p = INFINITY;  // projected size in pixels
    if (v.orthographic) {
        p = size[i] * v.focal;
    } else {
        const double d[3] = {means[3 * i] - v.eye[0], means[3 * i + 1] - v.eye[1], means[3 * i + 2] - v.eye[2]};
        const double gap = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - radius[i];
        if (gap > 0) p = size[i] * v.focal / gap;
    }
    double o = 1.0;
    if (tau > 0) o = band > 0 ? std::clamp((p - tau) / (tau * band), 0.0, 1.0) : (p >= tau ? 1.0 : 0.0);
    return (float)o;
}

// fn(outputs of this thread..., begin, end) over [0, len) in contiguous chunks, one per thread (ascending with the
// thread number), then each output's chunks concatenated in that order onto `out...` (parallel, in order).
template <class Fn, class... T>
void chunked(int64_t len, int nt, Fn fn, std::vector<T>&... out) {
    std::tuple<std::vector<std::vector<T>>...> parts{std::vector<std::vector<T>>(nt)...};
    if (len < (1 << 16)) nt = 1;  // under ~1 ms of work: a parallel region (waking a busy core) costs more
#pragma omp parallel num_threads(nt)
    {
        const int th = omp_get_thread_num(), nth = omp_get_num_threads();
        std::apply([&](auto&... p) { fn(p[th]..., len * th / nth, len * (th + 1) / nth); }, parts);
    }
    const auto append = [](auto& to, const auto& from) {
        size_t total = to.size();
        for (const auto& part : from) total += part.size();
        to.reserve(total);
        for (const auto& part : from) to.insert(to.end(), part.begin(), part.end());
    };
    std::apply([&](const auto&... p) { (append(out, p), ...); }, parts);
}

// Pairs ascending by their splat (each splat once: order is a permutation): an LSD radix sort, 11 bits a pass, as
// many passes as splat indices below n need (3 for up to 8 G).
void sort_by_splat(std::vector<std::pair<int32_t, float>>& v, int64_t n) {
    std::vector<std::pair<int32_t, float>> tmp(v.size());
    for (int shift = 0; (int64_t(1) << shift) < n; shift += 11) {
        std::vector<size_t> at(2049, 0);
        for (const auto& e : v) ++at[((uint32_t)e.first >> shift & 2047) + 1];
        for (int d = 0; d < 2048; ++d) at[d + 1] += at[d];
        for (const auto& e : v) tmp[at[(uint32_t)e.first >> shift & 2047]++] = e;
        v.swap(tmp);
    }
}

// The cut by its definition, over every node: each interior node's o, the weights top-down level by level, each
// leaf's; what the top-down walk falls back to when most of the tree is reached.
Cut cut_flat(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
             const int32_t* order, const View& v, double tau, double band, int nt, Halt& halt) {
    const int64_t n = levels[1], m = levels[num_levels - 1] - n;
    std::vector<float> open(m), weight(m);  // o and the weight reaching each interior node
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
    std::vector<float> leaf_w(n);
    Cut c;
    if (halt.now()) return c;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int64_t id = 0; id < n; ++id) {
        if (halt.at(id)) continue;
        const int64_t p = m > 0 ? parent(0, id) : -1;
        leaf_w[order[id]] = p < 0 ? 1.0f : weight[p] * open[p];
    }
    if (halt.now()) return c;
    // (a thread that stopped counting early, halt being sticky, writes nothing: never more than it counted)
    auto compact = [nt, &halt](const std::vector<float>& w, auto drawn, std::vector<int32_t>& idx,
                               std::vector<float>& out) {
        const int64_t len = (int64_t)w.size();
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
                idx.resize(counts[nth]), out.resize(counts[nth]);
            }
            int64_t at = counts[th];
            for (int64_t i = b; i < e && !halt.at(i); ++i) {
                const float d = drawn(i);
                if (d > 0.0f) idx[at] = (int32_t)i, out[at++] = d;
            }
        }
    };
    compact(leaf_w, [&](int64_t i) { return leaf_w[i]; }, c.leaves, c.leaf_weights);
    if (halt.now()) return c;
    compact(weight, [&](int64_t i) { return weight[i] * (1.0f - open[i]); }, c.nodes, c.node_weights);
    return c;
}

}  // namespace

// Top down from the root, visiting only the nodes the cut reaches (a node is reached when its parent opens, o > 0):
// the cost follows the cut, not the scene (cut_flat once most of a large level is reached and most of it opens on;
// testing's cut_flat_above 0: always). A
// reached node of weight w (the root 1) is drawn at w (1 - o) and passes w o to its children: the products the flat
// definition forms, so both give the same cut.
Cut cut(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
        const int32_t* order, const View& v, double tau, double band, int threads, const Stop& stop) {
    const int nt = team(threads);
    Halt halt(stop);
    const int64_t n = levels[1], m = levels[num_levels - 1] - n;
    Cut c;
    if (m == 0) {  // one splat: the leaf
        c.leaves.assign(n, 0);
        c.leaf_weights.assign(n, 1.0f);
        return c;
    }
    using Reached = std::pair<int64_t, float>;  // (interior index, weight reaching it)
    std::vector<Reached> frontier{{m - 1, 1.0f}}, next;
    std::vector<std::vector<Reached>> drawn(num_levels);  // per level, ascending
    std::vector<std::pair<int32_t, float>> leaves;  // (splat, weight) under the reached level-1 nodes
    std::vector<float> opens;  // the frontier's openings, where the fallback's check computed them
    const int64_t flat_above = cpu::testing::cut_flat_above.load(std::memory_order_relaxed);
    if (flat_above == 0) return cut_flat(means, radius, size, levels, num_levels, order, v, tau, band, nt, halt);
    for (int l = num_levels - 2; l >= 1; --l) {  // level l's reached nodes: frontier
        const int64_t reached = (int64_t)frontier.size();
        opens.clear();
        if (reached > flat_above && reached * 4 > levels[l + 1] - levels[l]) {
            // Most of a large level reached: the definition over every node costs less than walking (a walked entry
            // costs about 3 of its) once the walk would go on into most of the tree: here when over 3/4 of the
            // reached nodes open, on level 1 when their leaves (up to 8 each) would be over a third of the splats.
            opens.resize(reached);
            int64_t opened = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : opened)
            for (int64_t f = 0; f < reached; ++f) {
                opens[f] = opening(means, radius, size, frontier[f].first, v, tau, band);
                opened += frontier[f].second * opens[f] > 0.0f;
            }
            if (l == 1 ? opened * BRANCHING * 3 > n : opened * 4 > reached * 3)
                return cut_flat(means, radius, size, levels, num_levels, order, v, tau, band, nt, halt);
        }
        if (halt.now()) return c;
        next.clear();
        // each reached node's o once: drawn at w (1 - o) on this level, w o passed to its children (level 1's: leaves)
        chunked(reached, nt, [&](std::vector<Reached>& out, std::vector<Reached>& down,
                                 std::vector<std::pair<int32_t, float>>& below, int64_t b, int64_t e) {
            for (int64_t f = b; f < e && !halt.at(f); ++f) {
                const auto [i, w] = frontier[f];
                const float o = opens.empty() ? opening(means, radius, size, i, v, tau, band) : opens[f];
                const float kept = w * (1.0f - o);
                if (kept > 0.0f) out.push_back({i, kept});
                const float passed = w * o;
                if (!(passed > 0.0f)) continue;
                const int64_t id = i + n, first = levels[l - 1] + BRANCHING * (id - levels[l]);
                for (int64_t child = first; child < std::min(first + BRANCHING, levels[l]); ++child) {
                    if (l == 1)
                        below.push_back({order[child], passed});
                    else
                        down.push_back({child - n, passed});
                }
            }
        }, drawn[l], next, leaves);
        std::swap(frontier, next);
    }
    if (halt.now()) return c;
    // the leaves ascending by splat
    if ((int64_t)leaves.size() * 16 < n) {  // few: sort them
        sort_by_splat(leaves, n);
    } else {  // many: place them by splat (order is a permutation) and keep the drawn in splat order
        std::vector<float> w(n, 0.0f);
#pragma omp parallel for num_threads(nt) schedule(static)
        for (int64_t j = 0; j < (int64_t)leaves.size(); ++j)
            if (!halt.at(j)) w[leaves[j].first] = leaves[j].second;
        leaves.clear();
        chunked(n, nt, [&](std::vector<std::pair<int32_t, float>>& out, int64_t b, int64_t e) {
            for (int64_t i = b; i < e && !halt.at(i); ++i)
                if (w[i] > 0.0f) out.push_back({(int32_t)i, w[i]});
        }, leaves);
    }
    c.leaves.resize(leaves.size());
    c.leaf_weights.resize(leaves.size());
    for (size_t j = 0; j < leaves.size(); ++j) c.leaves[j] = leaves[j].first, c.leaf_weights[j] = leaves[j].second;
    for (int l = 1; l < num_levels; ++l)
        for (const Reached& r : drawn[l]) c.nodes.push_back((int32_t)r.first), c.node_weights.push_back(r.second);
    return c;
}

}  // namespace gbv::lod
