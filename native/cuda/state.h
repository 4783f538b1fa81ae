// A renderer's device state and the frame steps that use it (nvcc only), one file per concern:
// binning.cu (the stage and each mode's finish, tile lists of splats, CUB scans and sorts, the frame), duplex.cu
// (cells and their canonical order), blend.cu (the blend and box-average kernels), interop.cu (CUDA-GL textures),
// renderer.cu (the class: locking, uploads, results).
#pragma once

#include <cuda_gl_interop.h>  // includes GL/gl.h (Debian/Ubuntu: libgl-dev)
#include <cuda_runtime.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <mutex>

#include "buffers.h"
#include "gbv/args.h"
#include "gbv/common.h"
#include "gbv/popfree.h"
#include "gbv/preprocess.h"
#include "gbv/ray3d.h"
#include "renderer.h"

namespace gbv::cuda {

namespace detail {
constexpr int THREADS = 256;  // threads per block of the one-dimensional kernels
inline int blocks(int64_t n, int per = THREADS) { return (int)((n + per - 1) / per); }

// Device counters of a frame: visible splats, visible cells, tile-splat pairs outside their cell's tiles, expanded
// tile-list entries, member slots in runs of equal depth (duplex).
enum Counter { VISIBLE = 0, CELLS_VISIBLE = 1, CELL_MISSES = 2, EXPANDED = 3, RUN_SLOTS = 4, NUM_COUNTERS = 5 };
}  // namespace detail

struct State {
    template <typename T>
    using Buf = detail::DeviceBuffer<T>;

    const int device;
    std::mutex mutex;  // one upload or render at a time: they share every buffer below
    std::string failed;  // the DeviceFailed reason once one was thrown: every later call throws it again
    bool has_scene = false, has_cells = false;  // false until an upload succeeds (buffers may be freed before)
    uint64_t generation = 0;  // of the uploaded scene (Renderer::scene)
    int64_t n = 0;
    int k = 1;
    Buf<float> means, scales, quats, opacities, sh, filter_3d, weight_sh;
    bool has_filter = false;
    int weight_k = 0;
    // a level-of-detail cut drawn in place (upload_lod, upload_cut): the hierarchy's lod_m interior nodes are rows
    // n.. of the scene's arrays above; frame splat i is row cut_rows[i] with its opacity times cut_weights[i]
    int64_t lod_m = 0, cut_count = 0;
    bool has_lod = false, has_cut = false;
    uint64_t cut_generation = 0;  // of the uploaded cut rows: every upload_cut starts a new one
    Buf<int32_t> cut_rows;
    Buf<float> cut_weights;
    // duplex cells (upload_cells) and their per-frame state
    int64_t m = 0, num_members = 0;
    Buf<float> cmeans, cscales, cquats;
    Buf<int32_t> coffsets, cmembers, cell_of;
    Buf<uint32_t> mkeys_in, mkeys_out, mvalues_in, mvalues_out, vis, vis_count, cell_touched, pair_counts, list;
    // member slots in runs of equal depth and their sort (duplex.cu: sort_runs)
    Buf<unsigned char> run_flags;
    Buf<uint32_t> run_slots, run_heads, run_keys[2], run_perm[2];
    Buf<uint64_t> run_numbers;
    Buf<uint64_t> cell_offsets, pair_ends;
    Buf<Cell2D> cells;
    Buf<TileRect> crects;
    Buf<uint2> cell_ranges;
    // the per-camera stage (binning.cu: stage_kernel), valid while stage_ready and its key holds
    struct StageKey {
        uint64_t scene = 0;
        uint64_t cut = 0;  // the cut_generation drawn in place, 0: the scene's rows
        CameraParams cam = {};
        int sh_deg = 0;
        float reach = 0;
        int rules = 0;  // stage_rules
        bool operator==(const StageKey& o) const {
            return scene == o.scene && cut == o.cut && sh_deg == o.sh_deg && reach == o.reach && rules == o.rules &&
                   std::memcmp(&cam, &o.cam, sizeof cam) == 0;
        }
    } stage_key;
    bool stage_ready = false;
    Buf<StageSplat> stage;
    Buf<unsigned char> stage_ok;
    detail::Event ev_stage;
    // per frame
    Buf<Splat2D> splats;
    Buf<DepthPlane> planes;  // stochastic_popfree: per splat (popfree.h)
    Buf<RaySplat> rays;  // eval3d, stopthepop
    Buf<TileRect> rects;
    Buf<uint32_t> touched, values_in, values_out;
    Buf<uint64_t> offsets, keys_in, keys_out;
    Buf<uint2> ranges;
    Buf<unsigned char> temp;
    Buf<unsigned long long> counters;
    Buf<float> rgb, alpha, window, o_rgb, o_alpha, o_window;
    Buf<int32_t> evals, o_evals;
    Buf<float4> rgba;  // render_to_gl_texture's packed image
    Buf<int64_t> evals_total;
    detail::Event ev[4];
    detail::HostTotals totals;
    std::map<unsigned int, cudaGraphicsResource_t> textures;  // GL texture name -> its CUDA registration

    explicit State(int dev) : device(dev) {}
    State(const State&) = delete;
    State& operator=(const State&) = delete;
    ~State();  // interop.cu: registrations are dropped only where a GL context is current

    void forget_scene();

    // Frees every device buffer above (Renderer::release_buffers; each frame and upload ensures what it uses).
    // A buffer added above is added here (tests/render/test_cuda_host.py compares the two lists).
    void release_buffers() {
        const auto free = [](auto&... bufs) { (bufs.release(), ...); };
        free(means, scales, quats, opacities, sh, filter_3d, weight_sh, cmeans, cscales, cquats, coffsets, cmembers,
             cell_of, mkeys_in, mkeys_out, mvalues_in, mvalues_out, vis, vis_count, cell_touched, pair_counts, list,
             run_flags, run_slots, run_heads, run_keys[0], run_keys[1], run_perm[0], run_perm[1], run_numbers,
             cell_offsets, pair_ends, cells, crects, cell_ranges, stage, stage_ok, splats, planes, rays, rects, touched,
             values_in, values_out, offsets, keys_in, keys_out, ranges, temp, counters, rgb, alpha, window, o_rgb,
             o_alpha, o_window, evals, o_evals, rgba, evals_total, cut_rows, cut_weights);
    }

    // binning.cu
    // Inclusive prefix sum of count > 0 32-bit counts, accumulated in 64 bits, into ends (no wait).
    void inclusive_sum(const uint32_t* counts, uint64_t* ends, int count, const char* what);
    // The sum of `count` evaluation counts (64-bit accumulation), copied to the host.
    int64_t sum_evals(const int32_t* counts, int64_t count);
    // Sort (keys_in, values_in) into (keys_out, values_out) by bits [begin_bit, end_bit) of the keys (stable).
    void sort_pairs(int64_t count, int begin_bit, int end_bit);
    // Render into the device output buffers (o_* when supersampling, else the full-resolution ones); `cut`: the
    // uploaded level-of-detail cut in place of the scene's splats.
    void run(const RenderArgs& a, RenderResult& res, bool cut);
    // The tile lists of the frame's `count` splats (stopthepop: each tile's list sorted by its tile key).
    void bin_splats(int64_t count, Mode mode, int queue, const CameraParams& cam, int gx, int bits, uint64_t& total);
    // The sorted tile lists of `count` items (splats or cells) that touch `total` tiles: keys (tile, depth bits;
    // tile alone without by_depth) into keys_in, values (item indices) into values_in, sorted into keys_out and
    // values_out, tile ranges into `out_ranges`. ends: inclusive scan of `touched`.
    void tile_lists(int64_t count, const Splat2D* items, const TileRect* item_rects, const uint32_t* item_touched,
                    const uint64_t* ends, int gx, int bits, bool by_depth, uint64_t total, uint2* out_ranges);
    void tile_lists(int64_t count, const Cell2D* items, const TileRect* item_rects, const uint32_t* item_touched,
                    const uint64_t* ends, int gx, int bits, bool by_depth, uint64_t total, uint2* out_ranges);

    // duplex.cu
    void bin_duplex(const CameraParams& cam, int gx, int gy, int num_tiles, int bits, uint64_t& total,
                    uint64_t& sort_length);

    // blend.cu
    void blend(const RenderArgs& a, int gx, int gy, const uint32_t* tile_values);
    void pack_rgba(int64_t px, const float* rgb, const float* alpha);

    // interop.cu
    // rgba (w x h) into the texture's level 0, finished and unmapped when it returns.
    void copy_to_texture(unsigned int texture, int w, int h);
    void release_texture(unsigned int texture);
};

}  // namespace gbv::cuda
