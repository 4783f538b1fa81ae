// The depth order (frame.h): a parallel LSD radix sort of the visible splats' (depth bits, id) keys.
#include <algorithm>

#include "frame.h"

namespace gbv::cpu {
namespace {

// Three stable counting passes of 11, 11 and 10 bits over the 32 depth bits. Each pass splits its input into one
// static range per thread, in input order; each range counts its digits, an exclusive prefix sum over (digit, range)
// gives each range its first slot per digit, and each range moves its keys there in input order. Stable, so keys
// of equal depth bits keep the first pass's input order: ascending ids, as sorting the whole 64-bit keys would.
constexpr int DIGIT_BITS = 11, PASSES = 3;
constexpr int BUCKETS = 1 << DIGIT_BITS;
constexpr int MAX_RANGES = 64;  // bounds the histograms (ranges x BUCKETS) on many-core machines

int digit(uint64_t key, int pass) { return (int)(key >> (32 + DIGIT_BITS * pass)) & (BUCKETS - 1); }

// Input i of a pass: the first pass reads the stage's depth bits (the valid splats', in id order), later ones the
// previous keys.
template <bool FIRST>
bool input_key(const uint32_t* depth, const uint64_t* src, int64_t i, uint64_t& key) {
    if constexpr (FIRST) {
        if (depth[i] == NO_DEPTH) return false;
        key = depth_key(depth[i], (uint32_t)i);
    } else {
        key = src[i];
    }
    return true;
}

// One pass of digit `pass` over inputs [0, len) into dst (the first pass sizes dst and `also` to the visible count,
// between its two parallel loops: an allocation failure is a MemoryError, not an abort inside OpenMP). False when
// cancelled, dst then unspecified.
template <bool FIRST>
bool radix_pass(int pass, int64_t len, const uint32_t* depth, const uint64_t* src, std::vector<uint64_t>& dst,
                std::vector<uint64_t>& also, std::vector<int64_t>& hist, int ranges, FrameRun& run) {
#pragma omp parallel for num_threads(ranges) schedule(static, 1)
    for (int k = 0; k < ranges; ++k) {
        int64_t* h = hist.data() + (size_t)k * BUCKETS;
        std::fill(h, h + BUCKETS, 0);
        CancelPoll poll(run);
        uint64_t key;
        for (int64_t i = len * k / ranges; i < len * (k + 1) / ranges; ++i) {
            if (input_key<FIRST>(depth, src, i, key)) ++h[digit(key, pass)];
            if (poll(1)) break;
        }
    }
    if (run.cancelled()) return false;
    int64_t total = 0;
    for (int b = 0; b < BUCKETS; ++b)
        for (int k = 0; k < ranges; ++k) {
            const int64_t c = hist[(size_t)k * BUCKETS + b];
            hist[(size_t)k * BUCKETS + b] = total;
            total += c;
        }
    if (FIRST) {
        dst.resize(total);
        also.resize(total);
    }
    uint64_t* out = dst.data();
#pragma omp parallel for num_threads(ranges) schedule(static, 1)
    for (int k = 0; k < ranges; ++k) {
        int64_t* slot = hist.data() + (size_t)k * BUCKETS;
        CancelPoll poll(run);
        uint64_t key;
        for (int64_t i = len * k / ranges; i < len * (k + 1) / ranges; ++i) {
            if (input_key<FIRST>(depth, src, i, key)) out[slot[digit(key, pass)]++] = key;
            if (poll(1)) break;
        }
    }
    return !run.cancelled();
}

}  // namespace

void depth_order(const Plane<uint32_t>& depth, std::vector<uint64_t>& order, std::vector<uint64_t>& scratch,
                 FrameRun& run) {
    const int ranges = std::max(1, std::min(omp_get_max_threads(), MAX_RANGES));
    std::vector<int64_t> hist((size_t)ranges * BUCKETS);
    // depth -> order -> scratch -> order
    if (!radix_pass<true>(0, (int64_t)depth.size(), depth.data(), nullptr, order, scratch, hist, ranges, run)) return;
    static_assert(PASSES == 3, "the passes below alternate order and scratch and end in order");
    const int64_t count = (int64_t)order.size();
    if (!radix_pass<false>(1, count, nullptr, order.data(), scratch, order, hist, ranges, run)) return;
    radix_pass<false>(2, count, nullptr, scratch.data(), order, scratch, hist, ranges, run);
}

}  // namespace gbv::cpu
