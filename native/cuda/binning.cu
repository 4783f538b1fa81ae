// The frame (State::run) and its splat steps: the per-camera stage and each mode's finish (one thread per splat),
// tile keys and a CUB radix sort of (tile, depth), tile ranges; the CUB scans, sorts and sums the other steps share.
#include <thrust/iterator/transform_iterator.h>

#include <algorithm>
#include <cub/cub.cuh>

#include "gbv/order.h"
#include "gbv/resort.h"
#include "state.h"

namespace gbv::cuda {
using namespace detail;
namespace {

// The row of the scene's arrays that frame splat i reads: cut_rows[i] for a level-of-detail cut drawn in place.
__device__ inline int64_t splat_row(const int32_t* rows, int64_t i) { return rows ? rows[i] : i; }

// The per-camera stage of every splat (stage_splat): kept while State::stage_key holds, shared by every mode's finish.
// rows, weights: a level-of-detail cut drawn in place (splat i is row rows[i], its opacity times weights[i], rounded
// as the gathered cut's: never fused into a later operation), else null.
__global__ void __launch_bounds__(THREADS)
    stage_kernel(int64_t n, const int32_t* rows, const float* weights, const float* means, const float* scales,
                 const float* quats, const float* opacities, const float* sh, const float* filter_3d, int k, int sh_deg,
                 CameraParams cam, int gx, int gy, float reach, int rules, StageSplat* stage, unsigned char* stage_ok) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i >= n) return;
    const int64_t row = splat_row(rows, i);
    const float opacity = weights ? __fmul_rn(opacities[row], weights[i]) : opacities[row];
    const SplatIn in{means + 3 * row,
                     scales + 3 * row,
                     quats + 4 * row,
                     opacity,
                     sh + (size_t)k * 3 * row,
                     filter_3d ? filter_3d[row] : 0.0f,
                     nullptr,
                     0,
                     -1};
    stage_ok[i] = stage_splat(in, sh_deg, rules, cam, gx, gy, reach, &stage[i]) ? 1 : 0;
}

// The mode's finish of every splat's stage (finish_splat; the per-pixel sorted modes: finish_ray_splat after it for
// stopthepop, instead of it for eval3d, with their ray data): Splat2D, tile rectangle, touched tile count; and where
// `planes` is given (stochastic_popfree) each splat's depth plane (popfree.h) from its mean, scale, quat and 3D filter.
// rows: as stage_kernel's.
__global__ void __launch_bounds__(THREADS)
    finish_kernel(int64_t n, const int32_t* rows, const float* means, const float* scales, const float* quats,
                  const float* filter_3d, DepthPlane* planes, const StageSplat* stage, const unsigned char* stage_ok,
                  int sh_deg, const float* weight_sh, int weight_k, const int32_t* cell_of, OitParams oit,
                  CameraParams cam, Mode mode, int gx, int gy, Splat2D* splats, RaySplat* rays, TileRect* rects,
                  uint32_t* touched, unsigned long long* visible) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    bool valid = false;
    if (i < n) {
        uint32_t count = 0;
        if (stage_ok[i]) {
            const int64_t row = splat_row(rows, i);
            const SplatIn in{means + 3 * row,
                             scales + 3 * row,
                             quats + 4 * row,
                             0.0f,
                             nullptr,
                             filter_3d ? filter_3d[row] : 0.0f,
                             weight_sh ? weight_sh + (size_t)weight_k * row : nullptr,
                             sh_degree_for_coeffs(weight_k),
                             cell_of ? cell_of[row] : -1};
            TileRect r;
            bool ok = mode == EVAL3D || finish_splat(in, stage[i], sh_deg, cam, mode, oit, gx, gy, &splats[i], &r);
            if (ok && per_pixel_sorted(mode))
                ok = finish_ray_splat(in, stage[i], cam, mode, gx, gy, &splats[i], &r, &rays[i]);
            if (ok) {
                splats[i].id = (int32_t)i;
                if (planes) planes[i] = splat_popfree_plane(cam, in);
                count = (uint32_t)((r.x1 - r.x0) * (r.y1 - r.y0));
                rects[i] = r;
                valid = true;
            }
        }
        touched[i] = count;
    }
    const int block_visible = __syncthreads_count(valid);
    if (threadIdx.x == 0 && block_visible) atomicAdd(visible, (unsigned long long)block_visible);
}

// One key per touched tile of each splat (Splat2D) or cell (Cell2D): tile id in the high 32 bits, depth bits
// (positive floats sort as uints) below; value = the item's index. Keys are written in item order and the radix
// sort is stable, so equal depths keep index order (as the CPU). wsr (by_depth false): the key is the tile alone,
// so the stable sort keeps splat-index order inside a tile. ends: inclusive scan of `touched`.
template <class Item>
__global__ void duplicate_kernel(int64_t n, const Item* items, const TileRect* rects, const uint32_t* touched,
                                 const uint64_t* ends, int gx, bool by_depth, uint64_t* keys, uint32_t* values) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i >= n || touched[i] == 0) return;
    uint64_t off = ends[i] - touched[i];
    const uint32_t depth_bits = by_depth ? float_bits(items[i].depth) : 0u;
    const TileRect r = rects[i];
    for (int ty = r.y0; ty < r.y1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx) {
            keys[off] = ((uint64_t)(ty * gx + tx) << 32) | depth_bits;
            values[off] = (uint32_t)i;
            ++off;
        }
}

// stopthepop:K's tile stage (gbv/resort.h): the lists sorted by (tile, centre depth) in (keys, values) get the key
// (tile, tile_depth_key) in (keys_to, values_to); a stable sort of those keeps centre-depth order among equal keys, as
// the CPU's tile_depth_order.
__global__ void tile_depth_keys_kernel(int64_t total, const uint64_t* keys, const uint32_t* values,
                                       const Splat2D* splats, const RaySplat* rays, CameraParams cam, int gx,
                                       uint64_t* keys_to, uint32_t* values_to) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (j >= total) return;
    const uint32_t tile = (uint32_t)(keys[j] >> 32), s = values[j];
    const float x0 = (float)((int)tile % gx * TILE) + 0.5f, y0 = (float)((int)tile / gx * TILE) + 0.5f;
    const float key = tile_depth_key(splats[s], rays[s], x0, y0, cam.cx, cam.cy, cam.fx, cam.fy);
    keys_to[j] = ((uint64_t)tile << 32) | float_bits(key);
    values_to[j] = s;
}

__global__ void ranges_kernel(int64_t total, const uint64_t* keys, uint2* ranges) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i >= total) return;
    const uint32_t tile = (uint32_t)(keys[i] >> 32);
    if (i == 0) {
        ranges[tile].x = 0;
    } else {
        const uint32_t prev = (uint32_t)(keys[i - 1] >> 32);
        if (tile != prev) {
            ranges[prev].y = (uint32_t)i;
            ranges[tile].x = (uint32_t)i;
        }
    }
    if (i == total - 1) ranges[tile].y = (uint32_t)total;
}

// A 32-bit count read as 64 bits. CUB's scans accumulate in the value type of their input, so a scan over the
// uint32 counts themselves wraps at 2^32 (and the wrapped total can pass the 2^31 guards).
struct WidenU64 {
    __host__ __device__ uint64_t operator()(uint32_t x) const { return x; }
};

// A 32-bit evaluation count read as 64 bits: their sum over a frame can pass 2^31.
struct WidenI64 {
    __host__ __device__ int64_t operator()(int32_t x) const { return x; }
};

template <class Item>
void sorted_tile_lists(State& s, int64_t count, const Item* items, const TileRect* item_rects,
                       const uint32_t* item_touched, const uint64_t* ends, int gx, int bits, bool by_depth,
                       uint64_t total, uint2* out_ranges) {
    s.keys_in.ensure(total);
    s.keys_out.ensure(total);
    s.values_in.ensure(total);
    s.values_out.ensure(total);
    duplicate_kernel<Item><<<blocks(count), THREADS>>>(count, items, item_rects, item_touched, ends, gx, by_depth,
                                                       s.keys_in.ptr, s.values_in.ptr);
    launched("duplicate_kernel");
    s.sort_pairs((int64_t)total, by_depth ? 0 : 32, 32 + bits);
    ranges_kernel<<<blocks(total), THREADS>>>((int64_t)total, s.keys_out.ptr, out_ranges);
    launched("ranges_kernel");
}

}  // namespace

void State::forget_scene() {
    has_scene = has_cells = has_lod = has_cut = false;
    n = m = num_members = lod_m = cut_count = 0;
    k = 1;
    weight_k = 0;
    has_filter = false;
    stage_ready = false;
}

// An int count: CUB's scan kernel with 64-bit offsets spills registers on sm_90.
void State::inclusive_sum(const uint32_t* counts, uint64_t* ends, int count, const char* what) {
    const auto in = thrust::make_transform_iterator(counts, WidenU64{});
    size_t temp_bytes = 0;
    CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, in, ends, count));
    temp.ensure(temp_bytes);
    CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.ptr, temp_bytes, in, ends, count));
    launched(what);
}

int64_t State::sum_evals(const int32_t* counts, int64_t count) {
    const auto in = thrust::make_transform_iterator(counts, WidenI64{});
    evals_total.ensure(1);
    size_t temp_bytes = 0;
    CUDA_CHECK(cub::DeviceReduce::Sum(nullptr, temp_bytes, in, evals_total.ptr, count));
    temp.ensure(temp_bytes);
    CUDA_CHECK(cub::DeviceReduce::Sum(temp.ptr, temp_bytes, in, evals_total.ptr, count));
    launched("cub::DeviceReduce::Sum (evaluations)");
    int64_t total = 0;
    CUDA_CHECK(cudaMemcpy(&total, evals_total.ptr, sizeof(total), cudaMemcpyDeviceToHost));
    return total;
}

void State::sort_pairs(int64_t count, int begin_bit, int end_bit) {
    size_t temp_bytes = 0;
    CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                               values_out.ptr, (int)count, begin_bit, end_bit));
    temp.ensure(temp_bytes);
    CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.ptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                               values_out.ptr, (int)count, begin_bit, end_bit));
    launched("cub::DeviceRadixSort::SortPairs");
}

void State::tile_lists(int64_t count, const Splat2D* items, const TileRect* item_rects, const uint32_t* item_touched,
                       const uint64_t* ends, int gx, int bits, bool by_depth, uint64_t total, uint2* out_ranges) {
    sorted_tile_lists(*this, count, items, item_rects, item_touched, ends, gx, bits, by_depth, total, out_ranges);
}

void State::tile_lists(int64_t count, const Cell2D* items, const TileRect* item_rects, const uint32_t* item_touched,
                       const uint64_t* ends, int gx, int bits, bool by_depth, uint64_t total, uint2* out_ranges) {
    sorted_tile_lists(*this, count, items, item_rects, item_touched, ends, gx, bits, by_depth, total, out_ranges);
}

void State::run(const RenderArgs& a, RenderResult& res, bool cut) {
    if (!has_scene) throw std::runtime_error("CUDA renderer: no scene uploaded (or its upload failed)");
    if (a.mode == DUPLEX && !has_cells) throw std::runtime_error("CUDA renderer: duplex needs cells (upload_cells)");
    if (cut && !has_cut) throw std::runtime_error("CUDA renderer: no level-of-detail cut uploaded (upload_cut)");
    if (a.mode == DUPLEX && cut)  // its cells are of the scene's splats: it draws a cut's gathered Scene
        throw std::runtime_error("CUDA renderer: duplex draws no level-of-detail cut in place");
    const bool in_cut = cut;
    const int64_t drawn = in_cut ? cut_count : n;  // the frame's splats
    const int32_t* rows = in_cut ? cut_rows.ptr : nullptr;
    const CameraParams& cam = a.cam;
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE, num_tiles = gx * gy;
    const int sh_deg = std::max(0, std::min(a.sh_degree, sh_degree_for_coeffs(k)));  // no reads past k coeffs
    splats.ensure(std::max<int64_t>(drawn, 1));
    if (per_pixel_sorted(a.mode)) rays.ensure(std::max<int64_t>(drawn, 1));
    rects.ensure(std::max<int64_t>(drawn, 1));
    touched.ensure(std::max<int64_t>(drawn, 1));
    offsets.ensure(std::max<int64_t>(drawn, 1));
    counters.ensure(NUM_COUNTERS);
    ranges.ensure(num_tiles);
    CUDA_CHECK(cudaMemsetAsync(counters.ptr, 0, NUM_COUNTERS * sizeof(unsigned long long)));
    CUDA_CHECK(cudaMemsetAsync(ranges.ptr, 0, sizeof(uint2) * num_tiles));

    CUDA_CHECK(cudaEventRecord(ev[0].e));
    // the stage: kept while its key holds (scene generation, the cut drawn in place, camera, SH degree, the
    // on-screen cull's reach, the presets' stage rules)
    const StageKey key{generation, in_cut ? cut_generation : 0, cam,
                       sh_deg,     stage_reach(a.mode, a.oit),  stage_rules(a.mode, a.oit)};
    res.stage_reused = stage_ready && stage_key == key;
    if (drawn > 0 && !res.stage_reused) {
        stage_ready = false;
        stage.ensure(drawn);
        stage_ok.ensure(drawn);
        stage_kernel<<<blocks(drawn), THREADS>>>(drawn, rows, in_cut ? cut_weights.ptr : nullptr, means.ptr, scales.ptr,
                                                 quats.ptr, opacities.ptr, sh.ptr, has_filter ? filter_3d.ptr : nullptr,
                                                 k, sh_deg, cam, gx, gy, key.reach, key.rules, stage.ptr, stage_ok.ptr);
        launched("stage_kernel");
        stage_key = key;
        stage_ready = true;
    }
    CUDA_CHECK(cudaEventRecord(ev_stage.e));
    if (drawn > 0) {
        const bool popfree = a.mode == STOCHASTIC_POPFREE;
        if (popfree) planes.ensure(drawn);
        finish_kernel<<<blocks(drawn), THREADS>>>(
            drawn, rows, means.ptr, scales.ptr, quats.ptr, has_filter ? filter_3d.ptr : nullptr,
            popfree ? planes.ptr : nullptr, stage.ptr, stage_ok.ptr, sh_deg, weight_k ? weight_sh.ptr : nullptr,
            weight_k, a.mode == DUPLEX ? cell_of.ptr : nullptr, a.oit, cam, a.mode, gx, gy, splats.ptr,
            per_pixel_sorted(a.mode) ? rays.ptr : nullptr, rects.ptr, touched.ptr, counters.ptr + VISIBLE);
        launched("finish_kernel");
    }
    CUDA_CHECK(cudaEventRecord(ev[1].e));

    int bits = 0;
    while ((1 << bits) < num_tiles) ++bits;
    uint64_t total = 0, sort_length = 0;
    if (a.mode == DUPLEX) {
        bin_duplex(cam, gx, gy, num_tiles, bits, total, sort_length);
    } else {
        bin_splats(drawn, a.mode, a.queue, cam, gx, bits, total);
        sort_length = a.mode == WSR ? 0 : total;
    }
    CUDA_CHECK(cudaEventRecord(ev[2].e));
    blend(a, gx, gy, a.mode == DUPLEX ? list.ptr : values_out.ptr);
    CUDA_CHECK(cudaEventRecord(ev[3].e));
    CUDA_CHECK(
        cudaMemcpyAsync(totals.p, counters.ptr, NUM_COUNTERS * sizeof(unsigned long long), cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaEventSynchronize(ev[3].e));
    CUDA_CHECK(cudaStreamSynchronize(0));
    float ms[3];
    for (int i = 0; i < 3; ++i) CUDA_CHECK(cudaEventElapsedTime(&ms[i], ev[i].e, ev[i + 1].e));
    float stage_ms = 0;
    CUDA_CHECK(cudaEventElapsedTime(&stage_ms, ev[0].e, ev_stage.e));
    res.stage_ms = res.stage_reused ? 0.0 : stage_ms;
    res.preprocess_ms = ms[0];
    res.sort_ms = ms[1];
    res.blend_ms = ms[2];
    res.visible = (int64_t)totals.p[VISIBLE];
    res.cells_visible = (int64_t)totals.p[CELLS_VISIBLE];
    res.cell_misses = (int64_t)totals.p[CELL_MISSES];
    res.sort_length = (int64_t)sort_length;
    res.pairs = (int64_t)total;
}

// One wait: the number of pairs, to size the key buffers.
void State::bin_splats(int64_t count, Mode mode, int queue, const CameraParams& cam, int gx, int bits,
                       uint64_t& total) {
    total = 0;
    if (count == 0) return;
    inclusive_sum(touched.ptr, offsets.ptr, (int)count, "cub::DeviceScan::InclusiveSum (tile-splat pairs)");
    CUDA_CHECK(cudaMemcpyAsync(totals.p, offsets.ptr + (count - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaStreamSynchronize(0));
    total = totals.p[0];
    if (total >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat pairs");
    if (total == 0) return;
    tile_lists(count, splats.ptr, rects.ptr, touched.ptr, offsets.ptr, gx, bits, mode != WSR, total, ranges.ptr);
    if (mode == STOPTHEPOP && queue > 0) {
        tile_depth_keys_kernel<<<blocks((int64_t)total), THREADS>>>(
            (int64_t)total, keys_out.ptr, values_out.ptr, splats.ptr, rays.ptr, cam, gx, keys_in.ptr, values_in.ptr);
        launched("tile_depth_keys_kernel");
        sort_pairs((int64_t)total, 0, 32 + bits);
    }
}

}  // namespace gbv::cuda
