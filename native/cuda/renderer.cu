// CUDA driver around the shared kernel headers: preprocess (one thread per splat), tile keys and a CUB radix
// sort of (tile, depth), tile ranges, blending (one 16x16 block per tile, splats batched through shared memory,
// early termination when every pixel of the block is done), box-average for supersampling.
#include <cuda_runtime.h>

#include <GL/gl.h>
#include <cuda_gl_interop.h>
#include <thrust/iterator/transform_iterator.h>

#include <algorithm>
#include <cub/cub.cuh>
#include <stdexcept>
#include <string>

#include "gbv/blend.h"
#include "gbv/preprocess.h"
#include "renderer.h"

namespace gbv::cuda {
namespace {

void check(cudaError_t e, const char* what) {
    if (e != cudaSuccess) throw std::runtime_error(std::string("CUDA error in ") + what + ": " + cudaGetErrorString(e));
}
#define CUDA_CHECK(x) check((x), #x)

// A device allocation that only grows (by 1.5x) and is reused between frames.
template <typename T>
struct DeviceBuffer {
    T* ptr = nullptr;
    size_t capacity = 0;
    void ensure(size_t n) {
        if (n <= capacity) return;
        release();
        const size_t count = std::max<size_t>(n + n / 2, 1);
        const cudaError_t e = cudaMalloc(&ptr, count * sizeof(T));
        if (e == cudaErrorMemoryAllocation) {
            cudaGetLastError();
            ptr = nullptr;
            throw std::runtime_error("CUDA out of device memory: could not allocate " +
                                     std::to_string((count * sizeof(T)) >> 20) + " MiB");
        }
        CUDA_CHECK(e);
        capacity = count;
    }
    void release() {
        if (ptr) cudaFree(ptr);
        ptr = nullptr;
        capacity = 0;
    }
    ~DeviceBuffer() { release(); }
};

__global__ void preprocess_kernel(int64_t n, const float* means, const float* scales, const float* quats,
                                  const float* opacities, const float* sh, const float* filter_3d, int k, int sh_deg,
                                  const float* weight_sh, int weight_k, const int32_t* cell_of, OitParams oit,
                                  CameraParams cam, Mode mode, int gx, int gy, Splat2D* splats, TileRect* rects,
                                  uint32_t* touched, unsigned long long* visible) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (i >= n) return;
    SplatIn in{means + 3 * i, scales + 3 * i, quats + 4 * i, opacities[i], sh + (size_t)k * 3 * i,
               filter_3d ? filter_3d[i] : 0.0f, weight_sh ? weight_sh + (size_t)weight_k * i : nullptr,
               sh_degree_for_coeffs(weight_k), cell_of ? cell_of[i] : -1};
    TileRect r;
    uint32_t count = 0;
    if (preprocess_splat(in, sh_deg, cam, mode, oit, gx, gy, &splats[i], &r)) {
        count = (uint32_t)((r.x1 - r.x0) * (r.y1 - r.y0));
        rects[i] = r;
        atomicAdd(visible, 1ull);
    }
    touched[i] = count;
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
    const uint32_t depth_bits = by_depth ? __float_as_uint(items[i].depth) : 0u;
    const TileRect r = rects[i];
    for (int ty = r.y0; ty < r.y1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx) {
            keys[off] = ((uint64_t)(ty * gx + tx) << 32) | depth_bits;
            values[off] = (uint32_t)i;
            ++off;
        }
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

// Duplex, one thread per cell: its visible splats to the front of its member slots (member order), then the cell's
// screen proxy (preprocess_cell); cell_touched = tiles of a cell with at least one visible splat. Counts the visible
// cells and the tiles of their visible splats outside the cell's rectangle (the CPU's cells_visible, cell_misses).
__global__ void cells_kernel(int64_t m, const float* cmeans, const float* cscales, const float* cquats,
                             const int32_t* coffsets, const int32_t* cmembers, const uint32_t* touched,
                             const TileRect* rects, CameraParams cam, int gx, int gy, uint32_t* vis,
                             uint32_t* vis_count, Cell2D* cells, TileRect* crects, uint32_t* cell_touched,
                             unsigned long long* cells_visible, unsigned long long* cell_misses) {
    const int64_t c = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (c >= m) return;
    uint32_t count = 0;
    for (int32_t j = coffsets[c]; j < coffsets[c + 1]; ++j)
        if (touched[cmembers[j]] > 0) vis[coffsets[c] + count++] = (uint32_t)cmembers[j];
    vis_count[c] = count;
    cell_touched[c] = 0;
    if (count == 0) return;
    CellIn in{cmeans + 3 * c, cscales + 3 * c, cquats + 4 * c};
    TileRect r;
    if (!preprocess_cell(in, cam, gx, gy, &cells[c], &r)) return;
    crects[c] = r;
    cell_touched[c] = (uint32_t)((r.x1 - r.x0) * (r.y1 - r.y0));
    unsigned long long misses = 0;
    for (uint32_t j = 0; j < count; ++j) misses += (unsigned long long)tiles_outside(rects[vis[coffsets[c] + j]], r);
    atomicAdd(cells_visible, 1ull);
    atomicAdd(cell_misses, misses);
}

// Duplex expansion: each (tile, cell) pair of the sorted list becomes its cell's visible splats.
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
    ranges[t] = r.y > r.x ? make_uint2(r.x > 0 ? (uint32_t)ends[r.x - 1] : 0u, (uint32_t)ends[r.y - 1])
                          : make_uint2(0u, 0u);
}

constexpr int BLOCK = TILE * TILE;

template <int M>
__global__ void __launch_bounds__(BLOCK)
    render_kernel(const uint2* ranges, const uint32_t* values, const Splat2D* splats, int W, int H, int gx,
                  float3 bg, OitParams oit, float* rgb, float* alpha, int32_t* evals, float* window) {
    __shared__ Splat2D batch[BLOCK];
    const int x = blockIdx.x * TILE + threadIdx.x, y = blockIdx.y * TILE + threadIdx.y;
    const int tid = threadIdx.y * TILE + threadIdx.x;
    const bool inside = x < W && y < H;
    const Vec2 pix = {x + 0.5f, y + 0.5f};
    const uint2 range = ranges[blockIdx.y * gx + blockIdx.x];
    bool done = !inside;
    float T = 1.0f, C[3] = {0.0f, 0.0f, 0.0f};
    TransmittanceWindow win = {1.0f, pix, {1.0f, 1.0f}};
    WsrSums wsr = {{0, 0, 0}, 0};
    DuplexState dst = {1.0f, 1.0f, -1, 0.0f, {0.0f, 0.0f, 0.0f}};
    int32_t ev = 0;
    for (uint32_t start = range.x; start < range.y; start += BLOCK) {
        if (__syncthreads_count(done) == BLOCK) break;
        if (start + tid < range.y) batch[tid] = splats[values[start + tid]];
        __syncthreads();
        const int count = (int)min((uint32_t)BLOCK, range.y - start);
        for (int j = 0; j < count && !done; ++j) {
            ++ev;
            if (M == GAUSSIAN_BLENDING)
                done = blend_gaussian(batch[j], win, C);
            else if (M == WSR)
                done = blend_wsr(batch[j], pix, wsr);
            else if (M == DUPLEX)
                done = blend_duplex(batch[j], pix, oit.et_grade, dst);
            else if (M == ANALYTIC)
                done = blend_analytic(batch[j], pix, T, C);
            else
                done = blend_scalar(batch[j], pix, T, C);
        }
    }
    if (!inside) return;
    if (M == GAUSSIAN_BLENDING) T = win.T;
    if (M == WSR) {
        const float inv = 1.0f / WSR_FIXED_SCALE;
        const float Cw[3] = {(float)wsr.C[0] * inv, (float)wsr.C[1] * inv, (float)wsr.C[2] * inv};
        resolve_weighted(Cw, (float)wsr.S * inv, oit.weight_background, 1.0f, C, &T);
    } else if (M == DUPLEX) {
        resolve_weighted(dst.C, dst.S, dst.T < DUPLEX_T_STOP ? 0.0f : oit.weight_background, dst.T, C, &T);
    }
    const size_t p = (size_t)y * W + x;
    rgb[p * 3] = C[0] + T * bg.x;
    rgb[p * 3 + 1] = C[1] + T * bg.y;
    rgb[p * 3 + 2] = C[2] + T * bg.z;
    alpha[p] = 1.0f - T;
    evals[p] = ev;
    if (window) {
        window[p * 2] = win.wh.x;
        window[p * 2 + 1] = win.wh.y;
    }
}

// Box-average N x N blocks (supersampling); evaluations are summed, window sizes converted to output pixels.
__global__ void downsample_kernel(int N, int w, int h, const float* rgb, const float* alpha, const int32_t* evals,
                                  const float* window, float* o_rgb, float* o_alpha, int32_t* o_evals,
                                  float* o_window) {
    const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
    if (x >= w || y >= h) return;
    float acc[6] = {0, 0, 0, 0, 0, 0};
    int32_t ev = 0;
    const int W = w * N;
    for (int sy = 0; sy < N; ++sy)
        for (int sx = 0; sx < N; ++sx) {
            const size_t q = (size_t)(y * N + sy) * W + (x * N + sx);
            for (int c = 0; c < 3; ++c) acc[c] += rgb[q * 3 + c];
            acc[3] += alpha[q];
            if (window) {
                acc[4] += window[q * 2];
                acc[5] += window[q * 2 + 1];
            }
            ev += evals[q];
        }
    const float inv = 1.0f / (N * N);
    const size_t p = (size_t)y * w + x;
    for (int c = 0; c < 3; ++c) o_rgb[p * 3 + c] = acc[c] * inv;
    o_alpha[p] = acc[3] * inv;
    o_evals[p] = ev;
    if (o_window) {
        o_window[p * 2] = acc[4] * inv / N;
        o_window[p * 2 + 1] = acc[5] * inv / N;
    }
}

__global__ void pack_rgba_kernel(int n, const float* rgb, const float* alpha, float4* out) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) out[i] = make_float4(rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2], alpha[i]);
}

int blocks(int64_t n, int per = 256) { return (int)((n + per - 1) / per); }

// A 32-bit count read as 64 bits. CUB's scans accumulate in the value type of their input, so a scan over the
// uint32 counts themselves wraps at 2^32 (and the wrapped total can pass the 2^31 guards).
struct WidenU64 {
    __host__ __device__ uint64_t operator()(uint32_t x) const { return x; }
};

// Device counters of a frame: visible splats, visible cells, cell misses (duplex).
enum Counter { VISIBLE = 0, CELLS_VISIBLE = 1, CELL_MISSES = 2, NUM_COUNTERS = 3 };

}  // namespace

struct Renderer::Impl {
    int64_t n = 0;
    int k = 1;
    DeviceBuffer<float> means, scales, quats, opacities, sh, filter_3d, weight_sh;
    bool has_filter = false;
    int weight_k = 0;
    // duplex cells (uploaded with each duplex frame) and their per-frame buffers
    int64_t m = 0;
    DeviceBuffer<float> cmeans, cscales, cquats;
    DeviceBuffer<int32_t> coffsets, cmembers, cell_of;
    DeviceBuffer<uint32_t> vis, vis_count, cell_touched, pair_counts, list;
    DeviceBuffer<uint64_t> cell_offsets, pair_ends;
    DeviceBuffer<Cell2D> cells;
    DeviceBuffer<TileRect> crects;
    DeviceBuffer<uint2> cell_ranges;
    DeviceBuffer<Splat2D> splats;
    DeviceBuffer<TileRect> rects;
    DeviceBuffer<uint32_t> touched, values_in, values_out;
    DeviceBuffer<uint64_t> offsets, keys_in, keys_out;
    DeviceBuffer<uint2> ranges;
    DeviceBuffer<unsigned char> temp;
    DeviceBuffer<unsigned long long> counters;
    DeviceBuffer<float> rgb, alpha, window, o_rgb, o_alpha, o_window;
    DeviceBuffer<int32_t> evals, o_evals;
    DeviceBuffer<float4> rgba;
    cudaEvent_t ev[4];

    Impl() {
        for (auto& e : ev) CUDA_CHECK(cudaEventCreate(&e));
    }
    ~Impl() {
        for (auto& e : ev) cudaEventDestroy(e);
    }

    // Inclusive prefix sum of n > 0 32-bit counts, accumulated in 64 bits into ends; returns the total.
    uint64_t inclusive_sum(const uint32_t* counts, uint64_t* ends, int64_t n) {
        const auto in = thrust::make_transform_iterator(counts, WidenU64{});
        size_t temp_bytes = 0;
        CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, in, ends, n));
        temp.ensure(temp_bytes);
        CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.ptr, temp_bytes, in, ends, n));
        uint64_t total = 0;
        CUDA_CHECK(cudaMemcpy(&total, ends + (n - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
        return total;
    }

    // Render into the device output buffers (o_* when supersampling, else the full-resolution ones).
    void run(const CameraParams& cam, Mode mode, const OitParams& oit, int N, int sh_degree, const float bg[3],
             bool want_window, RenderResult& res) {
        if (n == 0) throw std::runtime_error("CUDA renderer: upload a scene before rendering");
        const int W = cam.width, H = cam.height;
        const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE, num_tiles = gx * gy;
        const int sh_deg = std::max(0, std::min(sh_degree, sh_degree_for_coeffs(k)));  // no reads past k coeffs
        splats.ensure(n);
        rects.ensure(n);
        touched.ensure(n);
        offsets.ensure(n);
        counters.ensure(NUM_COUNTERS);
        CUDA_CHECK(cudaMemset(counters.ptr, 0, NUM_COUNTERS * sizeof(unsigned long long)));

        CUDA_CHECK(cudaEventRecord(ev[0]));
        if (mode == DUPLEX && m == 0) throw std::runtime_error("CUDA renderer: duplex needs cells");
        preprocess_kernel<<<blocks(n), 256>>>(n, means.ptr, scales.ptr, quats.ptr, opacities.ptr, sh.ptr,
                                              has_filter ? filter_3d.ptr : nullptr, k, sh_deg,
                                              weight_k ? weight_sh.ptr : nullptr, weight_k,
                                              mode == DUPLEX ? cell_of.ptr : nullptr, oit, cam, mode, gx, gy,
                                              splats.ptr, rects.ptr, touched.ptr, counters.ptr + VISIBLE);
        CUDA_CHECK(cudaGetLastError());
        CUDA_CHECK(cudaEventRecord(ev[1]));

        int bits = 0;
        while ((1 << bits) < num_tiles) ++bits;
        ranges.ensure(num_tiles);
        CUDA_CHECK(cudaMemset(ranges.ptr, 0, sizeof(uint2) * num_tiles));
        uint64_t total = 0, sort_length = 0;
        if (mode == DUPLEX) {
            bin_duplex(cam, gx, gy, num_tiles, bits, total, sort_length);
        } else {
            bin_splats(mode, gx, num_tiles, bits, total);
            sort_length = mode == WSR ? 0 : total;
        }
        CUDA_CHECK(cudaEventRecord(ev[2]));
        render(mode, oit, W, H, gx, gy, N, bg, want_window, mode == DUPLEX ? list.ptr : values_out.ptr);
        CUDA_CHECK(cudaEventRecord(ev[3]));
        CUDA_CHECK(cudaEventSynchronize(ev[3]));
        float ms[3];
        for (int i = 0; i < 3; ++i) CUDA_CHECK(cudaEventElapsedTime(&ms[i], ev[i], ev[i + 1]));
        res.preprocess_ms = ms[0];
        res.sort_ms = ms[1];
        res.blend_ms = ms[2];
        unsigned long long count[NUM_COUNTERS];
        CUDA_CHECK(cudaMemcpy(count, counters.ptr, sizeof(count), cudaMemcpyDeviceToHost));
        res.visible = (int64_t)count[VISIBLE];
        res.cells_visible = (int64_t)count[CELLS_VISIBLE];
        res.cell_misses = (int64_t)count[CELL_MISSES];
        res.sort_length = (int64_t)sort_length;
        res.pairs = (int64_t)total;
    }

    // Tile lists of splats: one (tile, depth) key per touched tile (tile only for wsr), sorted by CUB.
    void bin_splats(Mode mode, int gx, int num_tiles, int bits, uint64_t& total) {
        total = inclusive_sum(touched.ptr, offsets.ptr, n);
        if (total >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat pairs");
        if (total > 0) {
            size_t temp_bytes = 0;
            keys_in.ensure(total);
            keys_out.ensure(total);
            values_in.ensure(total);
            values_out.ensure(total);
            duplicate_kernel<Splat2D><<<blocks(n), 256>>>(n, splats.ptr, rects.ptr, touched.ptr, offsets.ptr, gx,
                                                          mode != WSR, keys_in.ptr, values_in.ptr);
            CUDA_CHECK(cudaGetLastError());
            const int begin_bit = mode == WSR ? 32 : 0;
            CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in.ptr, keys_out.ptr,
                                                       values_in.ptr, values_out.ptr, (int)total, begin_bit,
                                                       32 + bits));
            temp.ensure(temp_bytes);
            CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.ptr, temp_bytes, keys_in.ptr, keys_out.ptr,
                                                       values_in.ptr, values_out.ptr, (int)total, begin_bit,
                                                       32 + bits));
            ranges_kernel<<<blocks(total), 256>>>((int64_t)total, keys_out.ptr, ranges.ptr);
            CUDA_CHECK(cudaGetLastError());
        }
    }

    // Duplex binning (KERNELS.md §8.3): cells with a visible splat projected; one CUB sort of (tile, cell depth);
    // every tile's cells expanded to their visible splats. total = expanded entries, sort_length = tile-cell pairs.
    void bin_duplex(const CameraParams& cam, int gx, int gy, int num_tiles, int bits, uint64_t& total,
                    uint64_t& sort_length) {
        vis.ensure(std::max<int64_t>(cmembers.capacity, 1));
        vis_count.ensure(m);
        cell_touched.ensure(m);
        cell_offsets.ensure(m);
        cells.ensure(m);
        crects.ensure(m);
        cells_kernel<<<blocks(m), 256>>>(m, cmeans.ptr, cscales.ptr, cquats.ptr, coffsets.ptr, cmembers.ptr,
                                         touched.ptr, rects.ptr, cam, gx, gy, vis.ptr, vis_count.ptr, cells.ptr,
                                         crects.ptr, cell_touched.ptr, counters.ptr + CELLS_VISIBLE,
                                         counters.ptr + CELL_MISSES);
        CUDA_CHECK(cudaGetLastError());
        const uint64_t pairs = inclusive_sum(cell_touched.ptr, cell_offsets.ptr, m);
        if (pairs >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-cell pairs");
        sort_length = pairs;
        total = 0;
        cell_ranges.ensure(num_tiles);
        CUDA_CHECK(cudaMemset(cell_ranges.ptr, 0, sizeof(uint2) * num_tiles));
        list.ensure(1);
        if (pairs == 0) return;
        keys_in.ensure(pairs);
        keys_out.ensure(pairs);
        values_in.ensure(pairs);
        values_out.ensure(pairs);
        duplicate_kernel<Cell2D><<<blocks(m), 256>>>(m, cells.ptr, crects.ptr, cell_touched.ptr, cell_offsets.ptr, gx,
                                                     true, keys_in.ptr, values_in.ptr);
        CUDA_CHECK(cudaGetLastError());
        size_t temp_bytes = 0;
        CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                                   values_out.ptr, (int)pairs, 0, 32 + bits));
        temp.ensure(temp_bytes);
        CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.ptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                                   values_out.ptr, (int)pairs, 0, 32 + bits));
        ranges_kernel<<<blocks(pairs), 256>>>((int64_t)pairs, keys_out.ptr, cell_ranges.ptr);
        pair_counts.ensure(pairs);
        pair_ends.ensure(pairs);
        pair_counts_kernel<<<blocks(pairs), 256>>>((int64_t)pairs, values_out.ptr, vis_count.ptr, pair_counts.ptr);
        CUDA_CHECK(cudaGetLastError());
        total = inclusive_sum(pair_counts.ptr, pair_ends.ptr, (int64_t)pairs);
        if (total >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat entries");
        list.ensure(std::max<uint64_t>(total, 1));
        expand_kernel<<<blocks(pairs), 256>>>((int64_t)pairs, values_out.ptr, vis_count.ptr, coffsets.ptr, vis.ptr,
                                              pair_ends.ptr, list.ptr);
        expand_ranges_kernel<<<blocks(num_tiles), 256>>>(num_tiles, cell_ranges.ptr, pair_ends.ptr, ranges.ptr);
        CUDA_CHECK(cudaGetLastError());
    }

    void render(Mode mode, const OitParams& oit, int W, int H, int gx, int gy, int N, const float bg[3],
                bool want_window, const uint32_t* tile_values) {
        const size_t px = (size_t)W * H;
        const bool window_on = want_window && mode == GAUSSIAN_BLENDING;
        rgb.ensure(px * 3);
        alpha.ensure(px);
        evals.ensure(px);
        if (window_on) window.ensure(px * 2);
        const dim3 grid(gx, gy), block(TILE, TILE);
        const float3 bgc = make_float3(bg[0], bg[1], bg[2]);
        float* win = window_on ? window.ptr : nullptr;
        const uint32_t* v = tile_values;
        switch (mode) {
            case GAUSSIAN_BLENDING:
                render_kernel<GAUSSIAN_BLENDING><<<grid, block>>>(ranges.ptr, v, splats.ptr, W, H, gx, bgc, oit,
                                                                   rgb.ptr, alpha.ptr, evals.ptr, win);
                break;
            case ANALYTIC:
                render_kernel<ANALYTIC><<<grid, block>>>(ranges.ptr, v, splats.ptr, W, H, gx, bgc, oit, rgb.ptr,
                                                          alpha.ptr, evals.ptr, win);
                break;
            case WSR:
                render_kernel<WSR><<<grid, block>>>(ranges.ptr, v, splats.ptr, W, H, gx, bgc, oit, rgb.ptr,
                                                     alpha.ptr, evals.ptr, win);
                break;
            case DUPLEX:
                render_kernel<DUPLEX><<<grid, block>>>(ranges.ptr, v, splats.ptr, W, H, gx, bgc, oit, rgb.ptr,
                                                        alpha.ptr, evals.ptr, win);
                break;
            default:
                render_kernel<SCALAR><<<grid, block>>>(ranges.ptr, v, splats.ptr, W, H, gx, bgc, oit, rgb.ptr,
                                                        alpha.ptr, evals.ptr, win);
        }
        CUDA_CHECK(cudaGetLastError());
        if (N > 1) {
            const int w = W / N, h = H / N;
            o_rgb.ensure((size_t)w * h * 3);
            o_alpha.ensure((size_t)w * h);
            o_evals.ensure((size_t)w * h);
            if (window_on) o_window.ensure((size_t)w * h * 2);
            const dim3 g2((w + 15) / 16, (h + 15) / 16);
            downsample_kernel<<<g2, block>>>(N, w, h, rgb.ptr, alpha.ptr, evals.ptr, win, o_rgb.ptr, o_alpha.ptr,
                                             o_evals.ptr, window_on ? o_window.ptr : nullptr);
            CUDA_CHECK(cudaGetLastError());
        }
    }
};

std::pair<bool, std::string> availability() {
    int count = 0;
    const cudaError_t e = cudaGetDeviceCount(&count);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, std::string("no usable CUDA device: ") + cudaGetErrorString(e)};
    }
    if (count == 0) return {false, "no CUDA device found"};
    cudaDeviceProp prop;
    CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
    if (prop.major < 7 || (prop.major == 7 && prop.minor < 5))
        return {false, std::string(prop.name) + " is older than sm_75, the oldest architecture built"};
    return {true, prop.name};
}

Renderer::Renderer() : impl_(nullptr) {
    const auto [ok, why] = availability();
    if (!ok) throw std::runtime_error(why);
    impl_ = new Impl();
}

Renderer::~Renderer() { delete impl_; }

int64_t Renderer::num_splats() const { return impl_->n; }

void Renderer::upload(const float* means, const float* scales, const float* quats, const float* opacities,
                      const float* sh, const float* filter_3d, int64_t n, int k) {
    Impl& m = *impl_;
    auto put = [](DeviceBuffer<float>& buf, const float* src, size_t count) {
        buf.ensure(count);
        CUDA_CHECK(cudaMemcpy(buf.ptr, src, count * sizeof(float), cudaMemcpyHostToDevice));
    };
    put(m.means, means, n * 3);
    put(m.scales, scales, n * 3);
    put(m.quats, quats, n * 4);
    put(m.opacities, opacities, n);
    put(m.sh, sh, (size_t)n * k * 3);
    m.has_filter = filter_3d != nullptr;
    if (filter_3d) put(m.filter_3d, filter_3d, n);
    m.n = n;
    m.k = k;
    m.weight_k = 0;
    m.m = 0;
}

void Renderer::upload_weights(const float* weight_sh, int64_t n, int weight_k) {
    Impl& m = *impl_;
    if (n != m.n) throw std::runtime_error("CUDA renderer: view weights for another scene size");
    m.weight_sh.ensure((size_t)n * weight_k);
    CUDA_CHECK(cudaMemcpy(m.weight_sh.ptr, weight_sh, (size_t)n * weight_k * sizeof(float), cudaMemcpyHostToDevice));
    m.weight_k = weight_k;
}

void Renderer::upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                            const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members) {
    Impl& m = *impl_;
    auto put = [](auto& buf, const auto* src, size_t count) {
        buf.ensure(std::max<size_t>(count, 1));
        if (count) CUDA_CHECK(cudaMemcpy(buf.ptr, src, count * sizeof(*src), cudaMemcpyHostToDevice));
    };
    put(m.cmeans, means, num_cells * 3);
    put(m.cscales, scales, num_cells * 3);
    put(m.cquats, quats, num_cells * 4);
    put(m.coffsets, offsets, num_cells + 1);
    put(m.cmembers, members, num_members);
    put(m.cell_of, cell_of, m.n);
    m.m = num_cells;
}

RenderResult Renderer::render(const CameraParams& cam, Mode mode, int supersample, int sh_degree, const float bg[3],
                              bool want_window, const OitParams& oit) {
    Impl& m = *impl_;
    RenderResult res;
    m.run(cam, mode, oit, supersample, sh_degree, bg, want_window, res);
    const int N = supersample, w = cam.width / N, h = cam.height / N;
    const size_t px = (size_t)w * h;
    const bool window_on = want_window && mode == GAUSSIAN_BLENDING;
    res.rgb.resize(px * 3);
    res.alpha.resize(px);
    res.evals.resize(px);
    CUDA_CHECK(cudaMemcpy(res.rgb.data(), N > 1 ? m.o_rgb.ptr : m.rgb.ptr, px * 3 * 4, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(res.alpha.data(), N > 1 ? m.o_alpha.ptr : m.alpha.ptr, px * 4, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(res.evals.data(), N > 1 ? m.o_evals.ptr : m.evals.ptr, px * 4, cudaMemcpyDeviceToHost));
    if (window_on) {
        res.window.resize(px * 2);
        CUDA_CHECK(cudaMemcpy(res.window.data(), N > 1 ? m.o_window.ptr : m.window.ptr, px * 2 * 4,
                              cudaMemcpyDeviceToHost));
    }
    return res;
}

void Renderer::render_to_gl_texture(unsigned int texture, const CameraParams& cam, Mode mode, int supersample,
                                    int sh_degree, const float bg[3], const OitParams& oit) {
    Impl& m = *impl_;
    RenderResult res;
    m.run(cam, mode, oit, supersample, sh_degree, bg, false, res);
    const int N = supersample, w = cam.width / N, h = cam.height / N;
    m.rgba.ensure((size_t)w * h);
    pack_rgba_kernel<<<blocks((int64_t)w * h), 256>>>(w * h, N > 1 ? m.o_rgb.ptr : m.rgb.ptr,
                                                      N > 1 ? m.o_alpha.ptr : m.alpha.ptr, m.rgba.ptr);
    CUDA_CHECK(cudaGetLastError());
    // Registered for this copy only: GL reuses the names of deleted textures, so a registration kept by texture id
    // could outlive its texture and point at a stale one.
    cudaGraphicsResource_t resource;
    CUDA_CHECK(cudaGraphicsGLRegisterImage(&resource, texture, GL_TEXTURE_2D, cudaGraphicsRegisterFlagsWriteDiscard));
    cudaError_t e = cudaGraphicsMapResources(1, &resource);
    if (e == cudaSuccess) {
        cudaArray_t array;
        e = cudaGraphicsSubResourceGetMappedArray(&array, resource, 0, 0);
        if (e == cudaSuccess)
            e = cudaMemcpy2DToArray(array, 0, 0, m.rgba.ptr, w * sizeof(float4), w * sizeof(float4), h,
                                    cudaMemcpyDeviceToDevice);
        const cudaError_t unmap = cudaGraphicsUnmapResources(1, &resource);
        if (e == cudaSuccess) e = unmap;
    }
    const cudaError_t unregister = cudaGraphicsUnregisterResource(resource);
    if (e == cudaSuccess) e = unregister;
    check(e, "render_to_gl_texture (copy into the GL texture)");
}

}  // namespace gbv::cuda
