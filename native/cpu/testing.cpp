// Test switches (testing.h).
#include "testing.h"

#include <cstring>

namespace gbv::cpu::testing {

std::atomic<bool> pixel_boxes{true};
std::atomic<int64_t> cut_flat_above{65536};
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

void record_lists(const std::vector<int64_t>& tile_start, const std::vector<uint64_t>& keys) {
    std::lock_guard<std::mutex> lock(captured_mutex);
    captured_starts = tile_start;
    captured_keys = keys;
}

std::pair<std::vector<int64_t>, std::vector<uint64_t>> captured_lists() {
    std::lock_guard<std::mutex> lock(captured_mutex);
    return {captured_starts, captured_keys};
}

}  // namespace gbv::cpu::testing
