// CUDA driver around the shared kernel headers: preprocess (one thread per splat), tile keys and a CUB radix
// sort of (tile, depth), tile ranges, blending (one 16x16 block per tile, splats batched through shared memory,
// early termination when every pixel of the block is done), box-average for supersampling. Duplex: each cell's
// visible splats in the CPU's canonical order (a segmented sort by depth, equal depths by splat_less), cells
// projected, one sort of (tile, cell depth), each tile's cells expanded to their splats.
#include <cuda_gl_interop.h>  // includes GL/gl.h (Debian/Ubuntu: libgl-dev)
#include <cuda_runtime.h>

#include <thrust/iterator/transform_iterator.h>

#include <algorithm>
#include <cub/cub.cuh>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>

#include "gbv/blend.h"
#include "gbv/order.h"
#include "gbv/preprocess.h"
#include "renderer.h"

namespace gbv::cuda {
namespace {

void check(cudaError_t e, const char* what) {
    if (e != cudaSuccess) throw std::runtime_error(std::string("CUDA error in ") + what + ": " + cudaGetErrorString(e));
}
#define CUDA_CHECK(x) check((x), #x)

// After each kernel launch or CUB call: a launch error names the kernel. Debug builds (no NDEBUG) also wait for it,
// so that a fault inside a kernel is reported with that kernel's name instead of at a later call.
void launched(const char* kernel) {
    check(cudaGetLastError(), kernel);
#ifndef NDEBUG
    check(cudaDeviceSynchronize(), kernel);
#endif
}

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
        if (e != cudaSuccess) {
            cudaGetLastError();
            ptr = nullptr;
            if (e == cudaErrorMemoryAllocation)
                throw std::runtime_error("CUDA out of device memory: could not allocate " +
                                         std::to_string((count * sizeof(T)) >> 20) + " MiB");
            check(e, "cudaMalloc");
        }
        capacity = count;
    }
    void release() {
        if (ptr) cudaFree(ptr);
        ptr = nullptr;
        capacity = 0;
    }
    DeviceBuffer() = default;
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    ~DeviceBuffer() { release(); }
};

// A CUDA event owned by its object: a renderer whose construction fails part way leaks none.
struct Event {
    cudaEvent_t e = nullptr;
    Event() { CUDA_CHECK(cudaEventCreate(&e)); }
    Event(const Event&) = delete;
    Event& operator=(const Event&) = delete;
    ~Event() {
        if (e) cudaEventDestroy(e);
    }
};

// Page-locked host words that device totals are copied into (several copies, one wait).
struct HostTotals {
    unsigned long long* p = nullptr;
    HostTotals() { CUDA_CHECK(cudaMallocHost(&p, 4 * sizeof(unsigned long long))); }
    HostTotals(const HostTotals&) = delete;
    HostTotals& operator=(const HostTotals&) = delete;
    ~HostTotals() {
        if (p) cudaFreeHost(p);
    }
};

constexpr int THREADS = 256;  // threads per block of the one-dimensional kernels
constexpr uint32_t INVISIBLE = 0xFFFFFFFFu;  // member sort key of a splat culled by preprocess: after every depth

// Device counters of a frame: visible splats, visible cells, tile-splat pairs outside their cell's tiles, expanded
// tile-list entries (duplex).
enum Counter { VISIBLE = 0, CELLS_VISIBLE = 1, CELL_MISSES = 2, EXPANDED = 3, NUM_COUNTERS = 4 };

using BlockSum = cub::BlockReduce<unsigned long long, THREADS>;

// Adds each block's total of `v` to *counter: one atomic per block, not per thread. Every thread of the block calls
// it (it synchronises the block).
__device__ void add_block_total(unsigned long long v, unsigned long long* counter) {
    __shared__ typename BlockSum::TempStorage temp;
    const unsigned long long sum = BlockSum(temp).Sum(v);
    if (threadIdx.x == 0 && sum) atomicAdd(counter, sum);
}

__global__ void __launch_bounds__(THREADS)
    preprocess_kernel(int64_t n, const float* means, const float* scales, const float* quats,
                      const float* opacities, const float* sh, const float* filter_3d, int k, int sh_deg,
                      const float* weight_sh, int weight_k, const int32_t* cell_of, OitParams oit, CameraParams cam,
                      Mode mode, int gx, int gy, Splat2D* splats, TileRect* rects, uint32_t* touched,
                      unsigned long long* visible) {
    const int64_t i = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    bool valid = false;
    if (i < n) {
        SplatIn in{means + 3 * i, scales + 3 * i, quats + 4 * i, opacities[i], sh + (size_t)k * 3 * i,
                   filter_3d ? filter_3d[i] : 0.0f, weight_sh ? weight_sh + (size_t)weight_k * i : nullptr,
                   sh_degree_for_coeffs(weight_k), cell_of ? cell_of[i] : -1};
        TileRect r;
        uint32_t count = 0;
        if (preprocess_splat(in, sh_deg, cam, mode, oit, gx, gy, &splats[i], &r)) {
            count = (uint32_t)((r.x1 - r.x0) * (r.y1 - r.y0));
            rects[i] = r;
            valid = true;
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

// Duplex, one thread per member slot: sort key (depth bits, INVISIBLE for a culled splat) and value (the splat) for
// the segmented sort of each cell's slots, and the cell's count of visible splats.
__global__ void member_keys_kernel(int64_t num_members, const int32_t* members, const int32_t* cell_of,
                                   const uint32_t* touched, const Splat2D* splats, uint32_t* keys, uint32_t* values,
                                   uint32_t* vis_count) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (j >= num_members) return;
    const int32_t s = members[j];
    const bool visible = touched[s] > 0;
    keys[j] = visible ? float_bits(splats[s].depth) : INVISIBLE;
    values[j] = (uint32_t)s;
    if (visible) atomicAdd(&vis_count[cell_of[s]], 1u);
}

// Duplex, one thread per member slot after the stable segmented sort by depth bits: splats of a cell with equal
// depth bits (a run) take their place by splat_less, the CPU's order (ties between identical keys by position).
// Runs are nearly always of length 1; the result goes to `vis`, each cell's visible splats first.
__global__ void canonical_order_kernel(int64_t num_members, const uint32_t* keys, const uint32_t* values,
                                       const int32_t* cell_of, const Splat2D* splats, uint32_t* vis) {
    const int64_t j = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (j >= num_members) return;
    const uint32_t key = keys[j], s = values[j];
    int64_t a = j, b = j + 1;
    if (key != INVISIBLE) {
        const int32_t c = cell_of[s];
        while (a > 0 && keys[a - 1] == key && cell_of[values[a - 1]] == c) --a;
        while (b < num_members && keys[b] == key && cell_of[values[b]] == c) ++b;
    }
    if (b - a == 1) {
        vis[j] = s;
        return;
    }
    const Splat2D& me = splats[s];
    int64_t rank = 0;
    for (int64_t i = a; i < b; ++i) {
        if (i == j) continue;
        const Splat2D& other = splats[values[i]];
        if (splat_less(other, me) || (i < j && !splat_less(me, other))) ++rank;
    }
    vis[a + rank] = s;
}

// Duplex, one thread per cell: the screen proxy (preprocess_cell) of a cell with a visible splat; cell_touched = its
// tiles (0 when culled). Counts the visible cells and the tile-list entries they expand to (tiles x visible splats).
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

// Duplex, one thread per member slot: tiles of a visible splat of a visible cell outside the cell's rectangle.
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
    PixelSums sums = {{C[0], C[1], C[2]}, M == GAUSSIAN_BLENDING ? win.T : T, 0.0f};
    if (M == WSR) sums = wsr_pixel_sums(wsr.C, wsr.S);
    if (M == DUPLEX) sums = {{dst.C[0], dst.C[1], dst.C[2]}, dst.T, dst.S};
    const size_t p = (size_t)y * W + x;
    const float bgc[3] = {bg.x, bg.y, bg.z};
    resolve_pixel((Mode)M, sums, oit.weight_background, bgc, rgb + p * 3, alpha + p);
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

int blocks(int64_t n, int per = THREADS) { return (int)((n + per - 1) / per); }

// A 32-bit count read as 64 bits. CUB's scans accumulate in the value type of their input, so a scan over the
// uint32 counts themselves wraps at 2^32 (and the wrapped total can pass the 2^31 guards).
struct WidenU64 {
    __host__ __device__ uint64_t operator()(uint32_t x) const { return x; }
};

// A 32-bit evaluation count read as 64 bits: their sum over a frame can pass 2^31.
struct WidenI64 {
    __host__ __device__ int64_t operator()(int32_t x) const { return x; }
};

// RGBA of n pixels for a GL_RGBA32F texture.
__global__ void pack_rgba_kernel(int64_t n, const float* rgb, const float* alpha, float4* out) {
    const int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) out[i] = make_float4(rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2], alpha[i]);
}

// The device's name if it can run the kernels (sm_75 or newer), else a reason.
std::pair<bool, std::string> usable(int device) {
    cudaDeviceProp prop;
    const cudaError_t e = cudaGetDeviceProperties(&prop, device);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, "CUDA device " + std::to_string(device) + ": " + cudaGetErrorString(e)};
    }
    if (prop.major < 7 || (prop.major == 7 && prop.minor < 5))
        return {false, std::string(prop.name) + " is older than sm_75, the oldest architecture built"};
    return {true, prop.name};
}

}  // namespace

struct Renderer::Impl {
    const int device;
    std::mutex mutex;  // one upload or render at a time: they share every buffer below
    bool has_scene = false, has_cells = false;  // false until an upload succeeds (buffers may be freed before)
    int64_t n = 0;
    int k = 1;
    DeviceBuffer<float> means, scales, quats, opacities, sh, filter_3d, weight_sh;
    bool has_filter = false;
    int weight_k = 0;
    // duplex cells (upload_cells) and their per-frame state
    int64_t m = 0, num_members = 0;
    DeviceBuffer<float> cmeans, cscales, cquats;
    DeviceBuffer<int32_t> coffsets, cmembers, cell_of;
    DeviceBuffer<uint32_t> mkeys_in, mkeys_out, mvalues_in, mvalues_out, vis, vis_count, cell_touched, pair_counts,
        list;
    DeviceBuffer<uint64_t> cell_offsets, pair_ends;
    DeviceBuffer<Cell2D> cells;
    DeviceBuffer<TileRect> crects;
    DeviceBuffer<uint2> cell_ranges;
    // per frame
    DeviceBuffer<Splat2D> splats;
    DeviceBuffer<TileRect> rects;
    DeviceBuffer<uint32_t> touched, values_in, values_out;
    DeviceBuffer<uint64_t> offsets, keys_in, keys_out;
    DeviceBuffer<uint2> ranges;
    DeviceBuffer<unsigned char> temp;
    DeviceBuffer<unsigned long long> counters;
    DeviceBuffer<float> rgb, alpha, window, o_rgb, o_alpha, o_window;
    DeviceBuffer<int32_t> evals, o_evals;
    DeviceBuffer<float4> rgba;  // render_to_gl_texture's packed image
    DeviceBuffer<int64_t> evals_total;
    Event ev[4];
    HostTotals totals;
    std::map<unsigned int, cudaGraphicsResource_t> textures;  // GL texture name -> its CUDA registration

    explicit Impl(int dev) : device(dev) {}
    Impl(const Impl&) = delete;
    Impl& operator=(const Impl&) = delete;
    ~Impl() {
        for (auto& [name, resource] : textures) cudaGraphicsUnregisterResource(resource);
        cudaGetLastError();
    }

    // The renderer's device, current on the calling thread (the runtime's current device is per thread).
    void use() const { CUDA_CHECK(cudaSetDevice(device)); }

    void forget_scene() {
        has_scene = has_cells = false;
        n = m = num_members = 0;
        k = 1;
        weight_k = 0;
        has_filter = false;
    }

    // Inclusive prefix sum of count > 0 32-bit counts, accumulated in 64 bits, into ends (no wait). An int count:
    // CUB's scan kernel with 64-bit offsets spills registers on sm_90.
    void inclusive_sum(const uint32_t* counts, uint64_t* ends, int count, const char* what) {
        const auto in = thrust::make_transform_iterator(counts, WidenU64{});
        size_t temp_bytes = 0;
        CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, in, ends, count));
        temp.ensure(temp_bytes);
        CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.ptr, temp_bytes, in, ends, count));
        launched(what);
    }

    // The sum of `count` evaluation counts (64-bit accumulation), copied to the host.
    int64_t sum_evals(const int32_t* counts, int64_t count) {
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

    // The texture's CUDA registration, mapped (registered at first use and kept: per-frame registration costs more
    // than the copy). A registration that no longer maps (the texture was deleted or respecified) is made again once.
    cudaGraphicsResource_t map_texture(unsigned int texture) {
        for (int attempt = 0; attempt < 2; ++attempt) {
            auto it = textures.find(texture);
            if (it == textures.end()) {
                cudaGraphicsResource_t resource;
                CUDA_CHECK(cudaGraphicsGLRegisterImage(&resource, texture, GL_TEXTURE_2D,
                                                       cudaGraphicsRegisterFlagsWriteDiscard));
                it = textures.emplace(texture, resource).first;
            }
            const cudaError_t e = cudaGraphicsMapResources(1, &it->second);
            if (e == cudaSuccess) return it->second;
            cudaGetLastError();
            cudaGraphicsUnregisterResource(it->second);
            cudaGetLastError();
            textures.erase(it);
            if (attempt == 1) check(e, "cudaGraphicsMapResources (GL texture)");
        }
        return nullptr;  // not reached
    }

    // rgba (w x h) into the texture's level 0, finished before the texture is unmapped (GL in another context may
    // sample it as soon as this returns).
    void copy_to_texture(unsigned int texture, int w, int h) {
        cudaGraphicsResource_t resource = map_texture(texture);
        cudaArray_t array;
        cudaError_t e = cudaGraphicsSubResourceGetMappedArray(&array, resource, 0, 0);
        if (e == cudaSuccess) {
            cudaChannelFormatDesc desc;
            cudaExtent extent;
            unsigned int flags;
            e = cudaArrayGetInfo(&desc, &extent, &flags, array);
            if (e == cudaSuccess && (extent.width != (size_t)w || extent.height != (size_t)h ||
                                     desc.x != 32 || desc.y != 32 || desc.z != 32 || desc.w != 32 ||
                                     desc.f != cudaChannelFormatKindFloat)) {
                cudaGraphicsUnmapResources(1, &resource);
                throw std::runtime_error("render_to_gl_texture: texture " + std::to_string(texture) + " is " +
                                         std::to_string(extent.width) + "x" + std::to_string(extent.height) +
                                         " (RGBA32F expected), the render " + std::to_string(w) + "x" +
                                         std::to_string(h));
            }
            if (e == cudaSuccess)
                e = cudaMemcpy2DToArray(array, 0, 0, rgba.ptr, w * sizeof(float4), w * sizeof(float4), h,
                                        cudaMemcpyDeviceToDevice);
            if (e == cudaSuccess) e = cudaStreamSynchronize(0);
        }
        const cudaError_t unmap = cudaGraphicsUnmapResources(1, &resource);
        if (e == cudaSuccess) e = unmap;
        check(e, "render_to_gl_texture (copy into the GL texture)");
    }

    // Sort (keys, values) by bits [begin_bit, end_bit) of the 64-bit keys (stable).
    void sort_pairs(int64_t count, int begin_bit, int end_bit) {
        size_t temp_bytes = 0;
        CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                                   values_out.ptr, (int)count, begin_bit, end_bit));
        temp.ensure(temp_bytes);
        CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.ptr, temp_bytes, keys_in.ptr, keys_out.ptr, values_in.ptr,
                                                   values_out.ptr, (int)count, begin_bit, end_bit));
        launched("cub::DeviceRadixSort::SortPairs");
    }

    // Render into the device output buffers (o_* when supersampling, else the full-resolution ones).
    void run(const CameraParams& cam, Mode mode, const OitParams& oit, int N, int sh_degree, const float bg[3],
             bool want_window, RenderResult& res) {
        if (!has_scene) throw std::runtime_error("CUDA renderer: no scene uploaded (or its upload failed)");
        if (mode == DUPLEX && !has_cells) throw std::runtime_error("CUDA renderer: duplex needs cells (upload_cells)");
        const int W = cam.width, H = cam.height;
        const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE, num_tiles = gx * gy;
        const int sh_deg = std::max(0, std::min(sh_degree, sh_degree_for_coeffs(k)));  // no reads past k coeffs
        splats.ensure(std::max<int64_t>(n, 1));
        rects.ensure(std::max<int64_t>(n, 1));
        touched.ensure(std::max<int64_t>(n, 1));
        offsets.ensure(std::max<int64_t>(n, 1));
        counters.ensure(NUM_COUNTERS);
        ranges.ensure(num_tiles);
        CUDA_CHECK(cudaMemsetAsync(counters.ptr, 0, NUM_COUNTERS * sizeof(unsigned long long)));
        CUDA_CHECK(cudaMemsetAsync(ranges.ptr, 0, sizeof(uint2) * num_tiles));

        CUDA_CHECK(cudaEventRecord(ev[0].e));
        if (n > 0) {
            preprocess_kernel<<<blocks(n), THREADS>>>(n, means.ptr, scales.ptr, quats.ptr, opacities.ptr, sh.ptr,
                                                      has_filter ? filter_3d.ptr : nullptr, k, sh_deg,
                                                      weight_k ? weight_sh.ptr : nullptr, weight_k,
                                                      mode == DUPLEX ? cell_of.ptr : nullptr, oit, cam, mode, gx, gy,
                                                      splats.ptr, rects.ptr, touched.ptr, counters.ptr + VISIBLE);
            launched("preprocess_kernel");
        }
        CUDA_CHECK(cudaEventRecord(ev[1].e));

        int bits = 0;
        while ((1 << bits) < num_tiles) ++bits;
        uint64_t total = 0, sort_length = 0;
        if (mode == DUPLEX) {
            bin_duplex(cam, gx, gy, num_tiles, bits, total, sort_length);
        } else {
            bin_splats(mode, gx, bits, total);
            sort_length = mode == WSR ? 0 : total;
        }
        CUDA_CHECK(cudaEventRecord(ev[2].e));
        render(mode, oit, W, H, gx, gy, N, bg, want_window, mode == DUPLEX ? list.ptr : values_out.ptr);
        CUDA_CHECK(cudaEventRecord(ev[3].e));
        CUDA_CHECK(cudaMemcpyAsync(totals.p, counters.ptr, NUM_COUNTERS * sizeof(unsigned long long),
                                   cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaEventSynchronize(ev[3].e));
        CUDA_CHECK(cudaStreamSynchronize(0));
        float ms[3];
        for (int i = 0; i < 3; ++i) CUDA_CHECK(cudaEventElapsedTime(&ms[i], ev[i].e, ev[i + 1].e));
        res.preprocess_ms = ms[0];
        res.sort_ms = ms[1];
        res.blend_ms = ms[2];
        res.visible = (int64_t)totals.p[VISIBLE];
        res.cells_visible = (int64_t)totals.p[CELLS_VISIBLE];
        res.cell_misses = (int64_t)totals.p[CELL_MISSES];
        res.sort_length = (int64_t)sort_length;
        res.pairs = (int64_t)total;
    }

    // Tile lists of splats: one (tile, depth) key per touched tile (tile only for wsr), sorted by CUB. One wait: the
    // number of pairs, to size the key buffers.
    void bin_splats(Mode mode, int gx, int bits, uint64_t& total) {
        total = 0;
        if (n == 0) return;
        inclusive_sum(touched.ptr, offsets.ptr, (int)n, "cub::DeviceScan::InclusiveSum (tile-splat pairs)");
        CUDA_CHECK(cudaMemcpyAsync(totals.p, offsets.ptr + (n - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaStreamSynchronize(0));
        total = totals.p[0];
        if (total >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat pairs");
        if (total == 0) return;
        keys_in.ensure(total);
        keys_out.ensure(total);
        values_in.ensure(total);
        values_out.ensure(total);
        duplicate_kernel<Splat2D><<<blocks(n), THREADS>>>(n, splats.ptr, rects.ptr, touched.ptr, offsets.ptr, gx,
                                                          mode != WSR, keys_in.ptr, values_in.ptr);
        launched("duplicate_kernel<Splat2D>");
        sort_pairs((int64_t)total, mode == WSR ? 32 : 0, 32 + bits);
        ranges_kernel<<<blocks(total), THREADS>>>((int64_t)total, keys_out.ptr, ranges.ptr);
        launched("ranges_kernel");
    }

    // Duplex binning (KERNELS.md §8.3): each cell's visible splats in canonical order; cells with a visible splat
    // projected; one CUB sort of (tile, cell depth); every tile's cells expanded to their visible splats.
    // total = expanded entries, sort_length = tile-cell pairs. One wait: both totals, to size the buffers.
    void bin_duplex(const CameraParams& cam, int gx, int gy, int num_tiles, int bits, uint64_t& total,
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
        if (num_members > 0) {
            mkeys_in.ensure(num_members);
            mkeys_out.ensure(num_members);
            mvalues_in.ensure(num_members);
            mvalues_out.ensure(num_members);
            vis.ensure(num_members);
            member_keys_kernel<<<blocks(num_members), THREADS>>>(num_members, cmembers.ptr, cell_of.ptr, touched.ptr,
                                                                  splats.ptr, mkeys_in.ptr, mvalues_in.ptr,
                                                                  vis_count.ptr);
            launched("member_keys_kernel");
            size_t temp_bytes = 0;
            CUDA_CHECK(cub::DeviceSegmentedSort::StableSortPairs(nullptr, temp_bytes, mkeys_in.ptr, mkeys_out.ptr,
                                                                 mvalues_in.ptr, mvalues_out.ptr, num_members, m,
                                                                 coffsets.ptr, coffsets.ptr + 1));
            temp.ensure(temp_bytes);
            CUDA_CHECK(cub::DeviceSegmentedSort::StableSortPairs(temp.ptr, temp_bytes, mkeys_in.ptr, mkeys_out.ptr,
                                                                 mvalues_in.ptr, mvalues_out.ptr, num_members, m,
                                                                 coffsets.ptr, coffsets.ptr + 1));
            launched("cub::DeviceSegmentedSort::StableSortPairs");
            canonical_order_kernel<<<blocks(num_members), THREADS>>>(num_members, mkeys_out.ptr, mvalues_out.ptr,
                                                                      cell_of.ptr, splats.ptr, vis.ptr);
            launched("canonical_order_kernel");
        }
        cells_kernel<<<blocks(m), THREADS>>>(m, cmeans.ptr, cscales.ptr, cquats.ptr, vis_count.ptr, cam, gx, gy,
                                             cells.ptr, crects.ptr, cell_touched.ptr, counters.ptr);
        launched("cells_kernel");
        if (num_members > 0) {
            cell_misses_kernel<<<blocks(num_members), THREADS>>>(num_members, cmembers.ptr, cell_of.ptr, touched.ptr,
                                                                  rects.ptr, cell_touched.ptr, crects.ptr,
                                                                  counters.ptr + CELL_MISSES);
            launched("cell_misses_kernel");
        }
        inclusive_sum(cell_touched.ptr, cell_offsets.ptr, (int)m, "cub::DeviceScan::InclusiveSum (tile-cell pairs)");
        CUDA_CHECK(cudaMemcpyAsync(totals.p, cell_offsets.ptr + (m - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpyAsync(totals.p + 1, counters.ptr + EXPANDED, sizeof(uint64_t), cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaStreamSynchronize(0));
        const uint64_t pairs = totals.p[0], expanded = totals.p[1];
        if (pairs >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-cell pairs");
        if (expanded >= (1ull << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 tile-splat entries");
        sort_length = pairs;
        total = expanded;
        if (pairs == 0) return;
        keys_in.ensure(pairs);
        keys_out.ensure(pairs);
        values_in.ensure(pairs);
        values_out.ensure(pairs);
        pair_counts.ensure(pairs);
        pair_ends.ensure(pairs);
        list.ensure(total);
        duplicate_kernel<Cell2D><<<blocks(m), THREADS>>>(m, cells.ptr, crects.ptr, cell_touched.ptr, cell_offsets.ptr,
                                                         gx, true, keys_in.ptr, values_in.ptr);
        launched("duplicate_kernel<Cell2D>");
        sort_pairs((int64_t)pairs, 0, 32 + bits);
        ranges_kernel<<<blocks(pairs), THREADS>>>((int64_t)pairs, keys_out.ptr, cell_ranges.ptr);
        launched("ranges_kernel (cells)");
        pair_counts_kernel<<<blocks(pairs), THREADS>>>((int64_t)pairs, values_out.ptr, vis_count.ptr,
                                                       pair_counts.ptr);
        launched("pair_counts_kernel");
        // expanded entries per pair; the scan's total equals `expanded` (cells_kernel counted the same products)
        inclusive_sum(pair_counts.ptr, pair_ends.ptr, (int)pairs, "cub::DeviceScan::InclusiveSum (entries)");
        expand_kernel<<<blocks(pairs), THREADS>>>((int64_t)pairs, values_out.ptr, vis_count.ptr, coffsets.ptr, vis.ptr,
                                                  pair_ends.ptr, list.ptr);
        launched("expand_kernel");
        expand_ranges_kernel<<<blocks(num_tiles), THREADS>>>(num_tiles, cell_ranges.ptr, pair_ends.ptr, ranges.ptr);
        launched("expand_ranges_kernel");
    }

    void render(Mode mode, const OitParams& oit, int W, int H, int gx, int gy, int N, const float bg[3],
                bool want_window, const uint32_t* tile_values) {
        const size_t px = (size_t)W * H;
        const bool window_on = want_window && mode == GAUSSIAN_BLENDING;
        rgb.ensure(px * 3);
        alpha.ensure(px);
        evals.ensure(px);
        if (window_on) window.ensure(px * 2);
        const uint32_t* v = tile_values;  // may be null when no tile has a splat (then none is read)
        const dim3 grid(gx, gy), block(TILE, TILE);
        const float3 bgc = make_float3(bg[0], bg[1], bg[2]);
        float* win = window_on ? window.ptr : nullptr;
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
        launched("render_kernel");
        if (N > 1) {
            const int w = W / N, h = H / N;
            o_rgb.ensure((size_t)w * h * 3);
            o_alpha.ensure((size_t)w * h);
            o_evals.ensure((size_t)w * h);
            if (window_on) o_window.ensure((size_t)w * h * 2);
            const dim3 g2((w + 15) / 16, (h + 15) / 16);
            downsample_kernel<<<g2, block>>>(N, w, h, rgb.ptr, alpha.ptr, evals.ptr, win, o_rgb.ptr, o_alpha.ptr,
                                             o_evals.ptr, window_on ? o_window.ptr : nullptr);
            launched("downsample_kernel");
        }
    }
};

std::pair<bool, std::string> availability() {
    int count = 0;
    cudaError_t e = cudaGetDeviceCount(&count);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, std::string("no usable CUDA device: ") + cudaGetErrorString(e)};
    }
    if (count == 0) return {false, "no CUDA device found"};
    int device = 0;
    e = cudaGetDevice(&device);
    if (e != cudaSuccess) {
        cudaGetLastError();
        return {false, std::string("no usable CUDA device: ") + cudaGetErrorString(e)};
    }
    return usable(device);
}

std::vector<int> gl_devices() {
    unsigned int count = 0;
    int devices[16];
    if (cudaGLGetDevices(&count, devices, 16, cudaGLDeviceListAll) != cudaSuccess) {
        cudaGetLastError();
        return {};
    }
    return std::vector<int>(devices, devices + std::min(count, 16u));
}

Renderer::Renderer(int device) {
    const auto [ok, why] = availability();
    if (!ok) throw std::runtime_error(why);
    if (device < 0) CUDA_CHECK(cudaGetDevice(&device));
    int count = 0;
    CUDA_CHECK(cudaGetDeviceCount(&count));
    if (device >= count)
        throw std::runtime_error("CUDA device " + std::to_string(device) + " does not exist (" +
                                 std::to_string(count) + " found)");
    const auto [dev_ok, dev_why] = usable(device);
    if (!dev_ok) throw std::runtime_error(dev_why);
    CUDA_CHECK(cudaSetDevice(device));
    impl_ = std::make_unique<Impl>(device);
}

Renderer::~Renderer() {
    cudaSetDevice(impl_->device);  // frees and texture unregistrations on the renderer's device
    impl_.reset();
}

int Renderer::device() const { return impl_->device; }

int64_t Renderer::num_splats() const {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return impl_->has_scene ? impl_->n : 0;
}

void Renderer::upload(const float* means, const float* scales, const float* quats, const float* opacities,
                      const float* sh, const float* filter_3d, int64_t n, int k) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
    m.forget_scene();
    if (n >= (1ll << 31)) throw std::runtime_error("CUDA renderer: more than 2^31 - 1 splats");
    auto put = [](DeviceBuffer<float>& buf, const float* src, size_t count) {
        buf.ensure(std::max<size_t>(count, 1));
        if (count) CUDA_CHECK(cudaMemcpy(buf.ptr, src, count * sizeof(float), cudaMemcpyHostToDevice));
    };
    put(m.means, means, n * 3);
    put(m.scales, scales, n * 3);
    put(m.quats, quats, n * 4);
    put(m.opacities, opacities, n);
    put(m.sh, sh, (size_t)n * k * 3);
    if (filter_3d) put(m.filter_3d, filter_3d, n);
    m.has_filter = filter_3d != nullptr;
    m.n = n;
    m.k = k;
    m.has_scene = true;
}

void Renderer::upload_weights(const float* weight_sh, int64_t n, int weight_k) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
    m.weight_k = 0;
    if (!m.has_scene || n != m.n) throw std::runtime_error("CUDA renderer: view weights for another scene size");
    m.weight_sh.ensure(std::max<size_t>((size_t)n * weight_k, 1));
    if (n)
        CUDA_CHECK(cudaMemcpy(m.weight_sh.ptr, weight_sh, (size_t)n * weight_k * sizeof(float),
                              cudaMemcpyHostToDevice));
    m.weight_k = weight_k;
}

void Renderer::upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                            const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
    m.has_cells = false;
    m.m = m.num_members = 0;
    if (!m.has_scene) throw std::runtime_error("CUDA renderer: upload a scene before its cells");
    if (num_cells >= (1ll << 31) || num_members >= (1ll << 31))
        throw std::runtime_error("CUDA renderer: more than 2^31 - 1 cells or cell members");
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
    m.num_members = num_members;
    m.has_cells = true;
}

RenderResult Renderer::render(const CameraParams& cam, Mode mode, int supersample, int sh_degree, const float bg[3],
                              bool want_window, const OitParams& oit) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
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

RenderResult Renderer::render_to_gl_texture(unsigned int texture, const CameraParams& cam, Mode mode, int supersample,
                                            int sh_degree, const float bg[3], const OitParams& oit) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
    const std::vector<int> gl = gl_devices();
    if (gl.empty())
        throw std::runtime_error("render_to_gl_texture: the OpenGL context current on this thread does not run on a "
                                 "CUDA device (or none is current)");
    if (std::find(gl.begin(), gl.end(), m.device) == gl.end())
        throw std::runtime_error("render_to_gl_texture: the current OpenGL context runs on CUDA device " +
                                 std::to_string(gl[0]) + ", this renderer on device " + std::to_string(m.device) +
                                 "; create the renderer on the GL device");
    RenderResult res;
    m.run(cam, mode, oit, supersample, sh_degree, bg, false, res);
    const int N = supersample, w = cam.width / N, h = cam.height / N;
    const int64_t px = (int64_t)w * h;
    m.rgba.ensure(std::max<int64_t>(px, 1));
    pack_rgba_kernel<<<blocks(px), THREADS>>>(px, N > 1 ? m.o_rgb.ptr : m.rgb.ptr, N > 1 ? m.o_alpha.ptr : m.alpha.ptr,
                                              m.rgba.ptr);
    launched("pack_rgba_kernel");
    res.evaluations = m.sum_evals(N > 1 ? m.o_evals.ptr : m.evals.ptr, px);
    m.copy_to_texture(texture, w, h);
    return res;
}

void Renderer::release_gl_texture(unsigned int texture) {
    Impl& m = *impl_;
    std::lock_guard<std::mutex> lock(m.mutex);
    m.use();
    const auto it = m.textures.find(texture);
    if (it == m.textures.end()) return;
    const cudaError_t e = cudaGraphicsUnregisterResource(it->second);
    m.textures.erase(it);
    check(e, "cudaGraphicsUnregisterResource (GL texture)");
}

}  // namespace gbv::cuda
