// Host check of the CUDA duplex canonical order (native/cuda/duplex.cu), built and run by test_duplex_order.py:
// the linear run sort (gbv/order.h: in_depth_run, same_depth_run, run_pass_key) gives exactly the order of the
// quadratic per-slot rank the kernel used before, and of a stable sort of each cell's visible splats by
// splat_less. Random cells with many equal depths and identical splats; prints "ok <slots> <run slots>".
#include <algorithm>
#include <cstdio>
#include <numeric>
#include <random>
#include <vector>

#include "gbv/order.h"

using namespace gbv;

int main() {
    std::mt19937 rng(12345);
    int64_t checked = 0, run_total = 0;
    for (int trial = 0; trial < 200; ++trial) {
        const int n = 1 + (int)(rng() % 400), cells = 1 + (int)(rng() % 12);
        const int depths = 1 + (int)(rng() % 4), values = 1 + (int)(rng() % 3);  // few values: many ties
        std::vector<Splat2D> splats(n);
        std::vector<int32_t> cell_of(n);
        std::vector<uint8_t> visible(n);
        for (int i = 0; i < n; ++i) {
            Splat2D& s = splats[i];
            s = Splat2D{};
            s.depth = 1.0f + (float)(rng() % depths);
            s.xy = {(float)(rng() % values), (float)(rng() % values)};
            s.opacity = 0.5f;
            s.color[0] = (float)(rng() % values);
            s.radius = (float)(rng() % values);
            s.log_min_alpha = -(float)(rng() % values);
            cell_of[i] = (int32_t)(rng() % cells);
            visible[i] = rng() % 5 != 0;
        }
        // members grouped by cell (offsets), in a random order inside each cell
        std::vector<int32_t> members(n);
        std::iota(members.begin(), members.end(), 0);
        std::shuffle(members.begin(), members.end(), rng);
        std::stable_sort(members.begin(), members.end(), [&](int a, int b) { return cell_of[a] < cell_of[b]; });
        std::vector<int> offsets(cells + 1, 0);
        for (int i = 0; i < n; ++i) offsets[cell_of[i] + 1]++;
        for (int c = 0; c < cells; ++c) offsets[c + 1] += offsets[c];
        // member_keys_kernel + the stable segmented sort by key
        std::vector<uint32_t> keys(n), vals(n);
        for (int j = 0; j < n; ++j) {
            const int s = members[j];
            keys[j] = visible[s] ? float_bits(splats[s].depth) : ORDER_INVISIBLE;
            vals[j] = (uint32_t)s;
        }
        for (int c = 0; c < cells; ++c) {
            std::vector<int> idx(offsets[c + 1] - offsets[c]);
            std::iota(idx.begin(), idx.end(), offsets[c]);
            std::stable_sort(idx.begin(), idx.end(), [&](int a, int b) { return keys[a] < keys[b]; });
            std::vector<uint32_t> k2, v2;
            for (int i : idx) k2.push_back(keys[i]), v2.push_back(vals[i]);
            std::copy(k2.begin(), k2.end(), keys.begin() + offsets[c]);
            std::copy(v2.begin(), v2.end(), vals.begin() + offsets[c]);
        }
        // the former kernel: per slot, its run by walking, then its rank in the run
        std::vector<uint32_t> old_vis(n);
        for (int64_t j = 0; j < n; ++j) {
            const uint32_t key = keys[j], s = vals[j];
            int64_t a = j, b = j + 1;
            if (key != ORDER_INVISIBLE) {
                const int32_t c = cell_of[s];
                while (a > 0 && keys[a - 1] == key && cell_of[vals[a - 1]] == c) --a;
                while (b < n && keys[b] == key && cell_of[vals[b]] == c) ++b;
            }
            int64_t rank = 0;
            for (int64_t i = a; i < b; ++i)
                if (i != j &&
                    (splat_less(splats[vals[i]], splats[s]) || (i < j && !splat_less(splats[s], splats[vals[i]]))))
                    ++rank;
            old_vis[a + rank] = s;
        }
        // the linear run sort, step by step as duplex.cu
        std::vector<uint32_t> vis(vals), run_slots;
        for (int64_t j = 0; j < n; ++j)
            if (in_depth_run(j, n, keys.data(), vals.data(), cell_of.data())) run_slots.push_back((uint32_t)j);
        const size_t R = run_slots.size();
        std::vector<uint32_t> run_numbers(R), perm(R);
        for (size_t i = 0; i < R; ++i)
            run_numbers[i] =
                (i == 0 || !same_depth_run(run_slots[i - 1], run_slots[i], keys.data(), vals.data(), cell_of.data())) +
                (i ? run_numbers[i - 1] : 0);
        std::iota(perm.begin(), perm.end(), 0u);
        for (int pass = 0; pass < RUN_PASSES; ++pass) {
            std::vector<uint32_t> key(R);
            for (size_t i = 0; i < R; ++i)
                key[perm[i]] = run_pass_key(pass, run_slots[perm[i]], run_numbers[perm[i]], vals.data(), splats.data());
            std::stable_sort(perm.begin(), perm.end(), [&](uint32_t a, uint32_t b) { return key[a] < key[b]; });
        }
        for (size_t i = 0; i < R; ++i) vis[run_slots[i]] = vals[run_slots[perm[i]]];
        // the definition: each cell's visible splats, stably sorted by splat_less (member order for ties)
        std::vector<uint32_t> ref;
        for (int c = 0; c < cells; ++c) {
            std::vector<uint32_t> v;
            for (int j = offsets[c]; j < offsets[c + 1]; ++j)
                if (visible[members[j]]) v.push_back((uint32_t)members[j]);
            std::stable_sort(v.begin(), v.end(),
                             [&](uint32_t a, uint32_t b) { return splat_less(splats[a], splats[b]); });
            ref.insert(ref.end(), v.begin(), v.end());
            for (int j = offsets[c]; j < offsets[c + 1]; ++j)
                if (!visible[members[j]]) ref.push_back(0);  // placeholders: compared below by position
        }
        for (int c = 0, o = 0; c < cells; ++c)
            for (int j = offsets[c]; j < offsets[c + 1]; ++j, ++o)
                if (keys[j] != ORDER_INVISIBLE && (vis[j] != ref[o])) {
                    std::printf("trial %d slot %d: run sort %u, definition %u\n", trial, j, vis[j], ref[o]);
                    return 1;
                }
        if (vis != old_vis) {
            std::printf("trial %d: run sort differs from the former rank\n", trial);
            return 1;
        }
        checked += n;
        run_total += (int64_t)R;
    }
    std::printf("ok %lld %lld\n", (long long)checked, (long long)run_total);
    return 0;
}
