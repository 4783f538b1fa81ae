// The blend (one 16x16 block per tile, splats batched through shared memory, early termination when every pixel of
// the block is done) and the box-average for supersampling. Blocks are numbered along one grid dimension (tile =
// blockIdx.x), so any image the arguments allow (2^31 - 1 pixels) fits CUDA's grid: its y and z dimensions stop
// at 65,535 blocks, 1,048,560 pixels of height.
#include "gbv/blend.h"
#include "gbv/ray3d.h"
#include "gbv/resort.h"
#include "gbv/stochastic.h"
#include "state.h"

namespace gbv::cuda {
using namespace detail;
namespace {

constexpr int BLOCK = TILE * TILE;

// Fast: gaussian_blending at the fast precision (blend_gaussian's Fast).
template <int M, bool Fast>
__global__ void __launch_bounds__(BLOCK)
    render_kernel(const uint2* ranges, const uint32_t* values, const Splat2D* splats, int W, int H, int gx, float3 bg,
                  OitParams oit, uint32_t frame_key, const DepthPlane* planes, float* rgb, float* alpha, int32_t* evals,
                  float* window) {
    __shared__ Splat2D batch[BLOCK];
    const int tile = blockIdx.x;
    const int x = (tile % gx) * TILE + threadIdx.x, y = (tile / gx) * TILE + threadIdx.y;
    const int tid = threadIdx.y * TILE + threadIdx.x;
    const bool inside = x < W && y < H;
    const Vec2 pix = {x + 0.5f, y + 0.5f};
    const uint2 range = ranges[tile];
    bool done = !inside;
    float T = 1.0f, C[3] = {0.0f, 0.0f, 0.0f};
    TransmittanceWindow win = {1.0f, pix, {1.0f, 1.0f}};
    WsrSums wsr = {{0, 0, 0}, 0};
    DuplexState dst = {1.0f, 1.0f, -1, 0.0f, {0.0f, 0.0f, 0.0f}};
    const uint32_t key = stochastic_sample_key(frame_key, x, y);
    float depth_key = -INFINITY;  // stochastic_popfree: the nearest kept fragment's (stochastic.h)
    int32_t ev = 0;
    for (uint32_t start = range.x; start < range.y; start += BLOCK) {
        if (__syncthreads_count(done) == BLOCK) break;
        if (start + tid < range.y) batch[tid] = splats[values[start + tid]];
        __syncthreads();
        const int count = (int)min((uint32_t)BLOCK, range.y - start);
        for (int j = 0; j < count && !done; ++j) {
            ++ev;
            if (M == GAUSSIAN_BLENDING)
                done = blend_gaussian(batch[j], win, C, Fast);
            else if (M == WSR)
                done = blend_wsr(batch[j], pix, wsr);
            else if (M == DUPLEX)
                done = blend_duplex(batch[j], pix, oit.et_grade, dst);
            else if (M == STOCHASTIC)
                done = blend_stochastic(batch[j], pix, key, T, C);
            else if (M == STOCHASTIC_POPFREE)
                blend_stochastic_popfree(batch[j], planes[batch[j].id], pix, key, T, depth_key, C);
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

// The list of a tile as gbv/resort.h's walk reads it: entry i is splat values[first + i].
struct DeviceListSource {
    const uint32_t* values;
    const Splat2D* splats;
    const RaySplat* rays;
    uint32_t first;
    __device__ const Splat2D& splat(int i) const { return splats[values[first + i]]; }
    __device__ const RaySplat& ray(int i) const { return rays[values[first + i]]; }
};

// The per-pixel sorted modes (eval3d, stopthepop: gbv/resort.h), one thread per pixel of a 16x16 block: stopthepop's
// hierarchy ending in the queue of K = `queue` (hier_walk, the list in the tile stage's order: bin_splats), in
// registers and local memory; K = 0 (and eval3d): the exact order by selection, each pass taking the nearest fragment
// after the last one blended (depth, then list position) until the pixel stops. evals as the CPU's.
__global__ void __launch_bounds__(BLOCK)
    sorted_kernel(const uint2* ranges, const uint32_t* values, const Splat2D* splats, const RaySplat* rays, Mode mode,
                  int queue, int W, int H, int gx, float3 bg, OitParams oit, float* rgb, float* alpha, int32_t* evals) {
    const int tile = blockIdx.x;
    const int x = (tile % gx) * TILE + threadIdx.x, y = (tile / gx) * TILE + threadIdx.y;
    if (x >= W || y >= H) return;
    const float px = x + 0.5f, py = y + 0.5f;
    const uint2 range = ranges[tile];
    const int n = (int)(range.y - range.x);
    AlphaState<Lanes1> st = {1.0f, {0.0f, 0.0f, 0.0f}};
    const int K = mode == EVAL3D ? 0 : queue;
    const auto fragment = [&](int i, Fragment& f) {
        const uint32_t id = values[range.x + i];
        f.entry = i;
        return sorted_fragment(mode, splats[id], rays[id], px, py, &f.alpha, &f.depth);
    };
    const auto color = [&](const Fragment& f) { return splats[values[range.x + f.entry]].color; };
    int32_t ev = n;
    if (K > 0) {
        const DeviceListSource src = {values, splats, rays, range.x};
        ev = hier_walk<DeviceListSource, NoTrace>(src, n, K, (tile % gx) * TILE, (tile / gx) * TILE, x, y, st);
    } else {
        Fragment last = {-INFINITY, 0.0f, -1};
        for (bool done = false; !done;) {
            Fragment best = {INFINITY, 0.0f, n}, f;
            for (int i = 0; i < n; ++i)
                if (fragment(i, f) && fragment_before(last, f) && fragment_before(f, best)) best = f;
            if (best.entry == n) break;
            done = blend_fragment<NoTrace>(best, color(best), st);
            last = best;
        }
    }
    const PixelSums sums = {{st.C[0], st.C[1], st.C[2]}, st.T, 0.0f};
    const size_t p = (size_t)y * W + x;
    const float bgc[3] = {bg.x, bg.y, bg.z};
    resolve_pixel(mode, sums, oit.weight_background, bgc, rgb + p * 3, alpha + p);
    evals[p] = ev;
}

// Box-average N x N blocks (supersampling), one thread per output pixel; evaluations are summed, window sizes
// converted to output pixels.
__global__ void downsample_kernel(int N, int w, int64_t px, const float* rgb, const float* alpha, const int32_t* evals,
                                  const float* window, float* o_rgb, float* o_alpha, int32_t* o_evals,
                                  float* o_window) {
    const int64_t p = blockIdx.x * (int64_t)blockDim.x + threadIdx.x;
    if (p >= px) return;
    const int64_t x = p % w, y = p / w;
    float acc[6] = {0, 0, 0, 0, 0, 0};
    int32_t ev = 0;
    const int64_t W = (int64_t)w * N;
    for (int sy = 0; sy < N; ++sy)
        for (int sx = 0; sx < N; ++sx) {
            const size_t q = (size_t)((y * N + sy) * W + (x * N + sx));
            for (int c = 0; c < 3; ++c) acc[c] += rgb[q * 3 + c];
            acc[3] += alpha[q];
            if (window) {
                acc[4] += window[q * 2];
                acc[5] += window[q * 2 + 1];
            }
            ev += evals[q];
        }
    const float inv = 1.0f / (N * N);
    for (int c = 0; c < 3; ++c) o_rgb[p * 3 + c] = acc[c] * inv;
    o_alpha[p] = acc[3] * inv;
    o_evals[p] = ev;
    if (o_window) {
        o_window[p * 2] = acc[4] * inv / N;
        o_window[p * 2 + 1] = acc[5] * inv / N;
    }
}

// RGBA of n pixels for a GL_RGBA32F texture.
__global__ void pack_rgba_kernel(int64_t n, const float* rgb, const float* alpha, float4* out) {
    const int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) out[i] = make_float4(rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2], alpha[i]);
}

template <int M, bool Fast = false>
void launch_blend(const State& s, int num_tiles, const uint32_t* values, int W, int H, int gx, float3 bg,
                  const RenderArgs& a, float* win) {
    const uint32_t frame_key = stochastic_frame_key(a.seed, a.frame);
    render_kernel<M, Fast><<<num_tiles, dim3(TILE, TILE)>>>(s.ranges.ptr, values, s.splats.ptr, W, H, gx, bg, a.oit,
                                                            frame_key, M == STOCHASTIC_POPFREE ? s.planes.ptr : nullptr,
                                                            s.rgb.ptr, s.alpha.ptr, s.evals.ptr, win);
}

}  // namespace

void State::blend(const RenderArgs& a, int gx, int gy, const uint32_t* tile_values) {
    const int W = a.cam.width, H = a.cam.height, N = a.supersample;
    const size_t px = (size_t)W * H;
    const bool window_on = a.want_window && a.mode == GAUSSIAN_BLENDING;
    rgb.ensure(px * 3);
    alpha.ensure(px);
    evals.ensure(px);
    if (window_on) window.ensure(px * 2);
    const uint32_t* v = tile_values;  // may be null when no tile has a splat (then none is read)
    const float3 bgc = make_float3(a.bg[0], a.bg[1], a.bg[2]);
    float* win = window_on ? window.ptr : nullptr;
    const int num_tiles = gx * gy;
    switch (a.mode) {
        case EVAL3D:
        case STOPTHEPOP:
            sorted_kernel<<<num_tiles, dim3(TILE, TILE)>>>(ranges.ptr, v, splats.ptr, rays.ptr, a.mode, a.queue, W, H,
                                                           gx, bgc, a.oit, rgb.ptr, alpha.ptr, evals.ptr);
            break;
        case GAUSSIAN_BLENDING:
            if (a.fast)
                launch_blend<GAUSSIAN_BLENDING, true>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            else
                launch_blend<GAUSSIAN_BLENDING>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        case ANALYTIC:
            launch_blend<ANALYTIC>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        case WSR:
            launch_blend<WSR>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        case DUPLEX:
            launch_blend<DUPLEX>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        case STOCHASTIC:
            launch_blend<STOCHASTIC>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        case STOCHASTIC_POPFREE:
            launch_blend<STOCHASTIC_POPFREE>(*this, num_tiles, v, W, H, gx, bgc, a, win);
            break;
        default:
            launch_blend<SCALAR>(*this, num_tiles, v, W, H, gx, bgc, a, win);
    }
    launched(per_pixel_sorted(a.mode) ? "sorted_kernel" : "render_kernel");
    if (N > 1) {
        const int w = W / N, h = H / N;
        const int64_t out_px = (int64_t)w * h;
        o_rgb.ensure(out_px * 3);
        o_alpha.ensure(out_px);
        o_evals.ensure(out_px);
        if (window_on) o_window.ensure(out_px * 2);
        downsample_kernel<<<blocks(out_px), THREADS>>>(N, w, out_px, rgb.ptr, alpha.ptr, evals.ptr, win, o_rgb.ptr,
                                                       o_alpha.ptr, o_evals.ptr, window_on ? o_window.ptr : nullptr);
        launched("downsample_kernel");
    }
}

void State::pack_rgba(int64_t px, const float* rgb_in, const float* alpha_in) {
    rgba.ensure(std::max<int64_t>(px, 1));
    pack_rgba_kernel<<<blocks(px), THREADS>>>(px, rgb_in, alpha_in, rgba.ptr);
    launched("pack_rgba_kernel");
}

}  // namespace gbv::cuda
