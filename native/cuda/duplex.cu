// Duplex binning (docs/modes.md#duplex): each cell's visible splats in the CPU's canonical order (a segmented radix
// sort by depth, then runs of equal depth sorted by splat_less: gbv/order.h), cells with a visible splat projected, one
// sort of (tile, cell depth), each tile's cells expanded to their splats.
#include <thrust/iterator/counting_iterator.h>

#include <cub/cub.cuh>

#include "gbv/order.h"
#include "state.h"

namespace gbv::cuda {
using namespace detail;
namespace {

using BlockSum = cub::BlockReduce<unsigned long long, THREADS>;

// Adds each block's total of `v` to *counter: one atomic per block, not per thread. Every thread of the block calls
// it (it synchronises the block).
__device__ void add_block_total(unsigned long long v, unsigned long long* counter) {
    __shared__ typename BlockSum::TempStorage temp;
    const unsigned long long sum = BlockSum(temp).Sum(v);
    if (threadIdx.x == 0 && sum) atomicAdd(counter, sum);
}

// One thread per member slot: sort key (depth bits, ORDER_INVISIBLE for a culled splat) and value (the splat) for
// the segmented sort of each cell's slots, and the cell's count of visible splats.
__global__ void member_keys_kernel(int64_t num_members, const int32_t* members, const int32_t* cell_of,
                                   const uint32_t* touched, const Splat2D* splats, uint32_t* keys, uint32_t* values,
                                   uint32_t* vis_count) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (j >= num_members) return;
    const int32_t s = members[j];
    const bool visible = touched[s] > 0;
    keys[j] = visible ? float_bits(splats[s].depth) : ORDER_INVISIBLE;
    values[j] = (uint32_t)s;
    if (visible) atomicAdd(&vis_count[cell_of[s]], 1u);
}

// One thread per member slot after the segmented sort: vis = the sorted splats (each cell's visible ones first),
// flags = the slots in runs of equal depth (in_depth_run), whose order run_sort_kernel's sort then fixes.
__global__ void run_flags_kernel(int64_t num_members, const uint32_t* keys, const uint32_t* values,
                                 const int32_t* cell_of, uint32_t* vis, unsigned char* flags) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (j >= num_members) return;
    vis[j] = values[j];
    flags[j] = in_depth_run(j, num_members, keys, values, cell_of);
}

// One thread per run slot i (run_slots: the slots in runs, in slot order): 1 where a new run starts.
__global__ void run_heads_kernel(int64_t count, const uint32_t* run_slots, const uint32_t* keys, const uint32_t* values,
                                 const int32_t* cell_of, uint32_t* heads) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i < count) heads[i] = i == 0 || !same_depth_run(run_slots[i - 1], run_slots[i], keys, values, cell_of);
}

// One thread per entry of the list being sorted (perm: indices into run_slots): its key for pass `pass`.
__global__ void run_keys_kernel(int64_t count, int pass, const uint32_t* perm, const uint32_t* run_slots,
                                const uint64_t* run_numbers, const uint32_t* values, const Splat2D* splats,
                                uint32_t* out) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i >= count) return;
    const uint32_t r = perm[i];
    out[i] = run_pass_key(pass, run_slots[r], (uint32_t)run_numbers[r], values, splats);
}

__global__ void iota_kernel(int64_t count, uint32_t* out) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i < count) out[i] = (uint32_t)i;
}

// vis[run_slots[i]] = the splat of run slot perm[i]: the run slots in canonical order.
__global__ void run_scatter_kernel(int64_t count, const uint32_t* run_slots, const uint32_t* perm,
                                   const uint32_t* values, uint32_t* vis) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i < count) vis[run_slots[i]] = values[run_slots[perm[i]]];
}

// One thread per cell: the screen proxy (preprocess_cell) of a cell with a visible splat; cell_touched = its tiles
// (0 when culled). Counts the visible cells and the tile-list entries they expand to (tiles x visible splats).
__global__ void __launch_bounds__(THREADS)
    cells_kernel(int64_t m, const float* cmeans, const float* cscales, const float* cquats, const uint32_t* vis_count,
                 CameraParams cam, int gx, int gy, Cell2D* cells, TileRect* crects, uint32_t* cell_touched,
                 unsigned long long* counters) {
    const int64_t c = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    bool valid = false;
    unsigned long long expanded = 0;
    if (c < m) {
        uint32_t tiles = 0;
        const uint32_t count = vis_count[c];
        TileRect r;
        CellIn in{cmeans + 3 * c, cscales + 3 * c, cquats + 4 * c};
        if (count > 0 && preprocess_cell(in, cam, gx, gy, &cells[c], &r)) {
            crects[c] = r;
            tiles = (uint32_t)((r.x1 - r.x0) * (r.y1 - r.y0));
            expanded = (unsigned long long)tiles * count;
            valid = true;
        }
        cell_touched[c] = tiles;
    }
    const int block_cells = __syncthreads_count(valid);
    if (threadIdx.x == 0 && block_cells) atomicAdd(&counters[CELLS_VISIBLE], (unsigned long long)block_cells);
    add_block_total(expanded, &counters[EXPANDED]);
}

// One thread per member slot: tiles of a visible splat of a visible cell outside the cell's rectangle.
__global__ void __launch_bounds__(THREADS)
    cell_misses_kernel(int64_t num_members, const int32_t* members, const int32_t* cell_of, const uint32_t* touched,
                       const TileRect* rects, const uint32_t* cell_touched, const TileRect* crects,
                       unsigned long long* misses) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    unsigned long long miss = 0;
    if (j < num_members) {
        const int32_t s = members[j];
        const int32_t c = cell_of[s];
        if (touched[s] > 0 && cell_touched[c] > 0) miss = (unsigned long long)tiles_outside(rects[s], crects[c]);
    }
    add_block_total(miss, misses);
}

// Expansion: each (tile, cell) pair of the sorted list becomes its cell's visible splats.
__global__ void pair_counts_kernel(int64_t pairs, const uint32_t* pair_cells, const uint32_t* vis_count,
                                   uint32_t* counts) {
    const int64_t k = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (k < pairs) counts[k] = vis_count[pair_cells[k]];
}

__global__ void expand_kernel(int64_t pairs, const uint32_t* pair_cells, const uint32_t* vis_count,
                              const int32_t* coffsets, const uint32_t* vis, const uint64_t* ends, uint32_t* list) {
    const int64_t k = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (k >= pairs) return;
    const uint32_t c = pair_cells[k], count = vis_count[c];
    const uint64_t out0 = ends[k] - count;
    for (uint32_t j = 0; j < count; ++j) list[out0 + j] = vis[coffsets[c] + j];
}

// Tile ranges of cell pairs -> tile ranges of the expanded splat list (ends: inclusive scan of the pair counts).
__global__ void expand_ranges_kernel(int num_tiles, const uint2* cell_ranges, const uint64_t* ends, uint2* ranges) {
    const int t = blockIdx.x * blockDim.x + threadIdx.x;
    if (t >= num_tiles) return;
    const uint2 r = cell_ranges[t];
    ranges[t] =
        r.y > r.x ? make_uint2(r.x > 0 ? (uint32_t)ends[r.x - 1] : 0u, (uint32_t)ends[r.y - 1]) : make_uint2(0u, 0u);
}

}  // namespace

// Member slots sorted by depth per cell (stable segmented radix sort: ties keep member order), runs of equal depth
// flagged and compacted (their count arrives with bin_duplex's one wait), then sorted by run_slot_less.
static void sort_members(State& s) {
    const int64_t nm = s.num_members;
    s.mkeys_in.ensure(nm);
    s.mkeys_out.ensure(nm);
    s.mvalues_in.ensure(nm);
    s.mvalues_out.ensure(nm);
    s.vis.ensure(nm);
    s.run_flags.ensure(nm);
    s.run_slots.ensure(nm);
    member_keys_kernel<<<blocks(nm), THREADS>>>(nm, s.cmembers.ptr, s.cell_of.ptr, s.touched.ptr, s.splats.ptr,
                                                s.mkeys_in.ptr, s.mvalues_in.ptr, s.vis_count.ptr);
    launched("member_keys_kernel");
    size_t temp_bytes = 0;
    CUDA_CHECK(cub::DeviceSegmentedSort::StableSortPairs(nullptr, temp_bytes, s.mkeys_in.ptr, s.mkeys_out.ptr,
                                                         s.mvalues_in.ptr, s.mvalues_out.ptr, nm, s.m, s.coffsets.ptr,
                                                         s.coffsets.ptr + 1));
    s.temp.ensure(temp_bytes);
    CUDA_CHECK(cub::DeviceSegmentedSort::StableSortPairs(s.temp.ptr, temp_bytes, s.mkeys_in.ptr, s.mkeys_out.ptr,
                                                         s.mvalues_in.ptr, s.mvalues_out.ptr, nm, s.m, s.coffsets.ptr,
                                                         s.coffsets.ptr + 1));
    launched("cub::DeviceSegmentedSort::StableSortPairs");
    run_flags_kernel<<<blocks(nm), THREADS>>>(nm, s.mkeys_out.ptr, s.mvalues_out.ptr, s.cell_of.ptr, s.vis.ptr,
                                              s.run_flags.ptr);
    launched("run_flags_kernel");
    const thrust::counting_iterator<uint32_t> slots(0);
    CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, temp_bytes, slots, s.run_flags.ptr, s.run_slots.ptr,
                                          s.counters.ptr + RUN_SLOTS, nm));
    s.temp.ensure(temp_bytes);
    CUDA_CHECK(cub::DeviceSelect::Flagged(s.temp.ptr, temp_bytes, slots, s.run_flags.ptr, s.run_slots.ptr,
                                          s.counters.ptr + RUN_SLOTS, nm));
    launched("cub::DeviceSelect::Flagged (depth runs)");
}

// The `count` run slots in canonical order: RUN_PASSES stable radix sorts of (key, index) pairs (gbv/order.h),
// O(count) work.
static void sort_runs(State& s, int64_t count) {
    s.run_heads.ensure(count);
    s.run_numbers.ensure(count);
    s.run_keys[0].ensure(count);
    s.run_keys[1].ensure(count);
    s.run_perm[0].ensure(count);
    s.run_perm[1].ensure(count);
    run_heads_kernel<<<blocks(count), THREADS>>>(count, s.run_slots.ptr, s.mkeys_out.ptr, s.mvalues_out.ptr,
                                                 s.cell_of.ptr, s.run_heads.ptr);
    launched("run_heads_kernel");
    s.inclusive_sum(s.run_heads.ptr, s.run_numbers.ptr, (int)count, "cub::DeviceScan::InclusiveSum (runs)");
    uint32_t *perm = s.run_perm[0].ptr, *sorted = s.run_perm[1].ptr;
    iota_kernel<<<blocks(count), THREADS>>>(count, perm);
    launched("iota_kernel");
    size_t temp_bytes = 0;
    CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, s.run_keys[0].ptr, s.run_keys[1].ptr, perm, sorted,
                                               (int)count));
    s.temp.ensure(temp_bytes);
    for (int pass = 0; pass < RUN_PASSES; ++pass) {
        run_keys_kernel<<<blocks(count), THREADS>>>(count, pass, perm, s.run_slots.ptr, s.run_numbers.ptr,
                                                    s.mvalues_out.ptr, s.splats.ptr, s.run_keys[0].ptr);
        launched("run_keys_kernel");
        CUDA_CHECK(cub::DeviceRadixSort::SortPairs(s.temp.ptr, temp_bytes, s.run_keys[0].ptr, s.run_keys[1].ptr, perm,
                                                   sorted, (int)count));
        launched("cub::DeviceRadixSort::SortPairs (depth runs)");
        std::swap(perm, sorted);
    }
    run_scatter_kernel<<<blocks(count), THREADS>>>(count, s.run_slots.ptr, perm, s.mvalues_out.ptr, s.vis.ptr);
    launched("run_scatter_kernel");
}

// total = expanded entries, sort_length = tile-cell pairs. One wait: both totals and the run slots, to size the
// buffers.
void State::bin_duplex(const CameraParams& cam, int gx, int gy, int num_tiles, int bits, uint64_t& total,
                       uint64_t& sort_length) {
    total = sort_length = 0;
    list.ensure(1);
    if (m == 0) return;
    vis_count.ensure(m);
    cell_touched.ensure(m);
    cell_offsets.ensure(m);
    cells.ensure(m);
    crects.ensure(m);
    cell_ranges.ensure(num_tiles);
    CUDA_CHECK(cudaMemsetAsync(vis_count.ptr, 0, sizeof(uint32_t) * m));
    CUDA_CHECK(cudaMemsetAsync(cell_ranges.ptr, 0, sizeof(uint2) * num_tiles));
    if (num_members > 0) sort_members(*this);
    cells_kernel<<<blocks(m), THREADS>>>(m, cmeans.ptr, cscales.ptr, cquats.ptr, vis_count.ptr, cam, gx, gy, cells.ptr,
                                         crects.ptr, cell_touched.ptr, counters.ptr);
    launched("cells_kernel");
    if (num_members > 0) {
        cell_misses_kernel<<<blocks(num_members), THREADS>>>(num_members, cmembers.ptr, cell_of.ptr, touched.ptr,
                                                             rects.ptr, cell_touched.ptr, crects.ptr,
                                                             counters.ptr + CELL_MISSES);
        launched("cell_misses_kernel");
    }
    inclusive_sum(cell_touched.ptr, cell_offsets.ptr, (int)m, "cub::DeviceScan::InclusiveSum (tile-cell pairs)");
    CUDA_CHECK(cudaMemcpyAsync(totals.p, cell_offsets.ptr + (m - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpyAsync(totals.p + 1, counters.ptr + EXPANDED, 2 * sizeof(uint64_t), cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaStreamSynchronize(0));
    const uint64_t pairs = totals.p[0], expanded = totals.p[1], run_count = num_members > 0 ? totals.p[2] : 0;
    if (pairs >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-cell pairs");
    if (expanded >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat entries");
    sort_length = pairs;
    total = expanded;
    if (pairs == 0) return;
    if (run_count > 0) sort_runs(*this, (int64_t)run_count);
    pair_counts.ensure(pairs);
    pair_ends.ensure(pairs);
    list.ensure(total);
    tile_lists(m, cells.ptr, crects.ptr, cell_touched.ptr, cell_offsets.ptr, gx, bits, true, pairs, cell_ranges.ptr);
    pair_counts_kernel<<<blocks(pairs), THREADS>>>((int64_t)pairs, values_out.ptr, vis_count.ptr, pair_counts.ptr);
    launched("pair_counts_kernel");
    // expanded entries per pair; the scan's total equals `expanded` (cells_kernel counted the same products)
    inclusive_sum(pair_counts.ptr, pair_ends.ptr, (int)pairs, "cub::DeviceScan::InclusiveSum (entries)");
    expand_kernel<<<blocks(pairs), THREADS>>>((int64_t)pairs, values_out.ptr, vis_count.ptr, coffsets.ptr, vis.ptr,
                                              pair_ends.ptr, list.ptr);
    launched("expand_kernel");
    expand_ranges_kernel<<<blocks(num_tiles), THREADS>>>(num_tiles, cell_ranges.ptr, pair_ends.ptr, ranges.ptr);
    launched("expand_ranges_kernel");
}

}  // namespace gbv::cuda
