// Binning (frame.h): each tile's list of splats, in a given (depth) order; for duplex, of cells expanded to their
// splats.
#include <algorithm>
#include <cstring>
#include <stdexcept>

#include "frame.h"
#include "gbv/order.h"
#include "gbv/preprocess.h"

namespace gbv::cpu {

// Binning of splats, in parallel: the order (or the splat order) is split into up to BIN_THREADS ranges; each range
// counts the tiles of its valid splats, a prefix sum over (tile, range) gives every range its slots in every tile,
// and each range writes its splat ids there. The ranges follow the order, so each tile's list comes out in that order
// (depth order from depth_order: no per-tile sort). The id buffer is sized between the two parallel passes (an
// allocation failure is a MemoryError, not an abort inside OpenMP). The counting pass also copies each splat's tile
// rectangle to its place in the order (`ranked`; empty for a splat that is not valid), so that the writing pass
// streams it instead of gathering rects[] in depth order a second time (the gather, a cache miss per splat, was half
// of the binning at 6 M splats). An empty rect marks a splat that is not valid (the finish writes one), so the gather
// reads no valid[] besides.
constexpr int BIN_THREADS = 8;  // bounds the counts buffer (ranges x tiles) on many-core machines
constexpr int64_t AHEAD = 16;  // prefetch distance of the gather, in splats

void bin_splats(const std::vector<TileRect>& rects, const uint64_t* order, int64_t count, int gx,
                std::vector<int64_t>& tile_start, std::vector<uint32_t>& ids, std::vector<RankedRect>& ranked,
                Stats& st, FrameRun& run) {
    const int num_tiles = (int)tile_start.size() - 1;
    auto t0 = Clock::now();
    const int ranges = std::max(1, std::min(omp_get_max_threads(), BIN_THREADS));
    if (gx > UINT16_MAX || num_tiles / gx > UINT16_MAX) throw std::length_error("bin_splats: tile grid over 2^16");
    std::vector<int64_t> slots((size_t)ranges * num_tiles, 0);  // [range][tile]: counts, then write cursors
    ranked.resize(count);
    int64_t visible = 0;
#pragma omp parallel for num_threads(ranges) schedule(static, 1) reduction(+ : visible)
    for (int k = 0; k < ranges; ++k) {
        int64_t* cnt = slots.data() + (size_t)k * num_tiles;
        CancelPoll poll(run);
        const int64_t end = count * (k + 1) / ranges;
        for (int64_t p = count * k / ranges; p < end; ++p) {
            const uint32_t i = order ? (uint32_t)order[p] : (uint32_t)p;
            if (order && p + AHEAD < end)  // the order's splats are scattered: fetch them ahead
                __builtin_prefetch(&rects[(uint32_t)order[p + AHEAD]]);
            const TileRect& r = rects[i];  // tile indices < 2^16 (MAX_IMAGE_SIZE x supersampling / TILE)
            if (r.x1 <= r.x0) {  // not valid
                ranked[p] = {0, 0, 0, 0};
                continue;
            }
            ++visible;
            ranked[p] = {(uint16_t)r.x0, (uint16_t)r.y0, (uint16_t)r.x1, (uint16_t)r.y1};
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) ++cnt[ty * gx + tx];
            if (poll(1 + (int64_t)(r.y1 - r.y0) * (r.x1 - r.x0))) break;
        }
    }
    if (run.cancelled()) return;
    int64_t total = 0;
    for (int t = 0; t < num_tiles; ++t) {
        tile_start[t] = total;
        for (int k = 0; k < ranges; ++k) {
            const int64_t c = slots[(size_t)k * num_tiles + t];
            slots[(size_t)k * num_tiles + t] = total;
            total += c;
        }
    }
    tile_start[num_tiles] = total;
    if ((size_t)total > ids.capacity()) {  // grown with slack, without copying: a moving camera's count varies
        ids = std::vector<uint32_t>();
        ids.reserve((size_t)total + (size_t)total / 8);
    }
    ids.resize(total);
#pragma omp parallel for num_threads(ranges) schedule(static, 1)
    for (int k = 0; k < ranges; ++k) {
        int64_t* cursor = slots.data() + (size_t)k * num_tiles;
        CancelPoll poll(run);
        for (int64_t p = count * k / ranges; p < count * (k + 1) / ranges; ++p) {
            const RankedRect r = ranked[p];
            if (r.x1 <= r.x0) continue;
            const uint32_t id = order ? (uint32_t)order[p] : (uint32_t)p;
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) ids[cursor[ty * gx + tx]++] = id;
            if (poll(1 + (int64_t)(r.y1 - r.y0) * (r.x1 - r.x0))) break;
        }
    }
    st.sort_ms += ms_since(t0);
    st.visible += visible;
    st.pairs += total;
}

// Duplex binning (docs/modes.md#duplex): each cell with at least one visible splat is projected as an ellipsoid; one
// depth sort of the (tile, cell depth, cell index) keys orders each tile's cells front to back; each tile's list
// is then its cells expanded to their visible splats, which follow a canonical order inside the cell
// (splat_less) so that the image does not depend on how the scene orders a cell's splats.
void bin_duplex(const SceneView& sc, const CameraParams& cam, const std::vector<Splat2D>& splats,
                const std::vector<TileRect>& rects, const std::vector<uint8_t>& valid, int gx, int gy,
                std::vector<int64_t>& tile_start, std::vector<uint32_t>& ids, Stats& st, FrameRun& run) {
    const int num_tiles = gx * gy;
    const int64_t m = sc.m;
    auto t0 = Clock::now();
    // visible members of each cell, canonically ordered; then the cell's screen proxy
    std::vector<int64_t> vis_start(m + 1, 0);
    CancelPoll poll(run);
    for (int64_t c = 0; c < m; ++c) {
        int64_t cnt = 0;
        for (int32_t j = sc.cell_offsets[c]; j < sc.cell_offsets[c + 1]; ++j) cnt += valid[sc.cell_members[j]];
        vis_start[c + 1] = vis_start[c] + cnt;
        if (poll(1 + sc.cell_offsets[c + 1] - sc.cell_offsets[c])) return;
    }
    std::vector<int32_t> vis(vis_start[m]);
    std::vector<Cell2D> cells(m);
    std::vector<TileRect> crects(m);
    std::vector<uint8_t> cvalid(m, 0);
#pragma omp parallel for schedule(static)
    for (int64_t c = 0; c < m; ++c) {
        if (run.cancelled()) continue;
        int64_t o = vis_start[c];
        for (int32_t j = sc.cell_offsets[c]; j < sc.cell_offsets[c + 1]; ++j)
            if (valid[sc.cell_members[j]]) vis[o++] = sc.cell_members[j];
        if (o == vis_start[c]) continue;
        std::sort(vis.begin() + vis_start[c], vis.begin() + o,
                  [&](int32_t a, int32_t b) { return splat_less(splats[a], splats[b]); });
        CellIn in{sc.cell_means + 3 * c, sc.cell_scales + 3 * c, sc.cell_quats + 4 * c};
        cvalid[c] = preprocess_cell(in, cam, gx, gy, &cells[c], &crects[c]);
    }
    if (run.cancelled()) return;
    st.preprocess_ms += ms_since(t0);

    t0 = Clock::now();
    std::vector<int64_t> cell_tile_start(num_tiles + 1, 0);
    int64_t visible_cells = 0, misses = 0;
    for (int64_t c = 0; c < m; ++c) {
        if (!cvalid[c]) continue;
        ++visible_cells;
        const TileRect& r = crects[c];
        const int64_t members = vis_start[c + 1] - vis_start[c];
        for (int ty = r.y0; ty < r.y1; ++ty)
            for (int tx = r.x0; tx < r.x1; ++tx) {
                ++cell_tile_start[ty * gx + tx + 1];
                tile_start[ty * gx + tx + 1] += members;
            }
        for (int64_t j = vis_start[c]; j < vis_start[c + 1]; ++j) misses += tiles_outside(rects[vis[j]], r);
        if (poll(1 + members + (int64_t)(r.y1 - r.y0) * (r.x1 - r.x0))) return;
    }
    for (int t = 0; t < num_tiles; ++t) {
        cell_tile_start[t + 1] += cell_tile_start[t];
        tile_start[t + 1] += tile_start[t];
    }
    const int64_t cell_pairs = cell_tile_start[num_tiles];
    std::vector<uint64_t> ckeys(cell_pairs);
    {
        std::vector<int64_t> cursor(cell_tile_start.begin(), cell_tile_start.end() - 1);
        for (int64_t c = 0; c < m; ++c) {
            if (!cvalid[c]) continue;
            uint32_t depth_bits;
            std::memcpy(&depth_bits, &cells[c].depth, 4);
            const uint64_t key = ((uint64_t)depth_bits << 32) | (uint32_t)c;
            const TileRect& r = crects[c];
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) ckeys[cursor[ty * gx + tx]++] = key;
            if (poll(1 + (int64_t)(r.y1 - r.y0) * (r.x1 - r.x0))) return;
        }
    }
    ids.resize(tile_start[num_tiles]);
#pragma omp parallel for schedule(dynamic, 4)
    for (int t = 0; t < num_tiles; ++t) {
        if (run.cancelled()) continue;
        std::sort(ckeys.begin() + cell_tile_start[t], ckeys.begin() + cell_tile_start[t + 1]);
        int64_t o = tile_start[t];
        for (int64_t k = cell_tile_start[t]; k < cell_tile_start[t + 1]; ++k) {
            const uint32_t c = (uint32_t)ckeys[k];
            for (int64_t j = vis_start[c]; j < vis_start[c + 1]; ++j) ids[o++] = (uint32_t)vis[j];
        }
    }
    if (run.cancelled()) return;
    st.sort_ms += ms_since(t0);
    int64_t visible = 0;  // splats that survive preprocess, as in the other modes
    for (uint8_t v : valid) visible += v;
    st.visible += visible;
    st.cells_visible += visible_cells;
    st.cell_misses += misses;
    st.sort_length += cell_pairs;
    st.pairs += tile_start[num_tiles];
}

}  // namespace gbv::cpu
