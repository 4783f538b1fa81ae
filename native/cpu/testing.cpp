// Test switches (testing.h).
#include "testing.h"

#include <cstring>

#include "half.h"
#include "omp_shim.h"
#include "preprocess_range.h"
#include "simd.h"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace gbv::cpu::testing {

std::atomic<bool> pixel_boxes{true};
std::atomic<bool> row_bands{true};
std::atomic<float> gaussian_band_margin{2.0f};
std::atomic<int64_t> cut_flat_above{65536};
std::atomic<int64_t> cut_stop_after{-1};
std::atomic<bool> poison_images{false};
std::atomic<bool> capture{false};

namespace {
std::mutex captured_mutex;
std::vector<uint8_t> captured;
std::vector<int64_t> captured_starts;
std::vector<uint64_t> captured_keys;
}  // namespace

void record_preprocess(const Splat2D* splats, const TileRect* rects, const uint8_t* valid, int64_t n) {
    constexpr size_t rec = 1 + sizeof(Splat2D) + sizeof(TileRect);
    std::lock_guard<std::mutex> lock(captured_mutex);
    captured.assign((size_t)n * rec, 0);
    for (int64_t i = 0; i < n; ++i) {
        uint8_t* p = captured.data() + (size_t)i * rec;
        p[0] = valid[i];
        if (!valid[i]) continue;
        std::memcpy(p + 1, &splats[i], sizeof(Splat2D));
        std::memcpy(p + 1 + sizeof(Splat2D), &rects[i], sizeof(TileRect));
    }
}

std::vector<uint8_t> captured_preprocess() {
    std::lock_guard<std::mutex> lock(captured_mutex);
    return captured;
}

void record_lists(const std::vector<int64_t>& tile_start, const std::vector<uint32_t>& ids,
                  const std::vector<Splat2D>& splats, bool depth_keys) {
    std::lock_guard<std::mutex> lock(captured_mutex);
    captured_starts = tile_start;
    captured_keys.resize(ids.size());
    for (size_t j = 0; j < ids.size(); ++j) {
        uint32_t bits = 0;
        if (depth_keys) std::memcpy(&bits, &splats[ids[j]].depth, 4);
        captured_keys[j] = depth_key(bits, ids[j]);
    }
}

std::pair<std::vector<int64_t>, std::vector<uint64_t>> captured_lists() {
    std::lock_guard<std::mutex> lock(captured_mutex);
    return {captured_starts, captured_keys};
}

#if defined(__x86_64__)
namespace {
__attribute__((target("f16c"))) void f16c_convert(const float* in, uint16_t* out) {
    _mm_storel_epi64(reinterpret_cast<__m128i*>(out), _mm_cvtps_ph(_mm_loadu_ps(in), _MM_FROUND_TO_NEAREST_INT));
}
}  // namespace
#endif

int64_t half_mismatches(uint64_t begin, uint64_t end) {
#if defined(__x86_64__)
    if (!simd::cpu_has_f16c()) return -1;
    int64_t bad = 0;
#pragma omp parallel for schedule(static) reduction(+ : bad)
    for (int64_t q = (int64_t)(begin / 4); q < (int64_t)(end / 4); ++q) {
        uint32_t bits[4];
        float in[4];
        uint16_t hw[4];
        for (int k = 0; k < 4; ++k) bits[k] = (uint32_t)(4 * q + k);
        std::memcpy(in, bits, sizeof in);
        f16c_convert(in, hw);
        for (int k = 0; k < 4; ++k) bad += hw[k] != half_bits(in[k]);
    }
    return bad;
#else
    (void)begin, (void)end;
    return -1;
#endif
}

}  // namespace gbv::cpu::testing
