// Blend: one work group per 16 x 16 block of output pixels, one invocation per pixel. With N x N supersampling the
// block covers N x N render tiles (the render resolution is N times the output's, tiles are 16 render pixels),
// which the group blends one after another and box-averages in shared memory, like the CPU driver's
// render-then-box_downsample. A tile's depth-sorted splats go through shared memory in batches of 256; the loop
// over batches stops when every pixel of the tile has terminated.
//
// Normally one dispatch does all N x N render tiles over their whole lists. On drivers that cap the loop
// iterations of an invocation (llvmpipe: 65535), the driver splits the work over several dispatches: a range of
// render tiles [subtile_begin, subtile_end) and a window [chunk_begin, chunk_end) of every tile's list. The
// per-sample state then survives between dispatches in `state` (load_state / store_state) and the box sum of
// the output pixel in `accum` (load_accum / store_accum); the dispatch that ends with store_accum == 0 writes
// the image.
//
// Compiled once per mode and sampling: the driver defines BLEND_MODE_<MODE> (SCALAR, MIP, ANALYTIC,
// GAUSSIAN_BLENDING, WSR, DUPLEX, STOCHASTIC, STOCHASTIC_POPFREE, EVAL3D or STOPTHEPOP) and SUPERSAMPLED (0 or 1);
// gaussian_blending's fast precision defines GB_FAST 1 (blend.glsl: blend_gaussian's `fast`).
// wsr walks index-ordered lists with no early termination; duplex walks cell-sorted lists, reads each splat's cell
// from `cell_of` and uses `oit`; stochastic hashes each sample's (seed, frame, X, Y) with the splat's index
// (stochastic.h). The per-pixel sorted modes (eval3d, stopthepop: resort.glsl) read the list directly, each pixel in
// its own order, in one dispatch (the driver refuses lists too long for a driver's loop cap).
#include "common.glsl"
#include "mathf.glsl"
#include "blend.glsl"
#include "kernel.glsl"
#include "ray3d.glsl"
#include "resort_key.glsl"
#include "resort.glsl"

#if defined(BLEND_MODE_SCALAR)
const int MODE = SCALAR;
#elif defined(BLEND_MODE_MIP)
const int MODE = MIP;
#elif defined(BLEND_MODE_ANALYTIC)
const int MODE = ANALYTIC;
#elif defined(BLEND_MODE_GAUSSIAN_BLENDING)
const int MODE = GAUSSIAN_BLENDING;
#elif defined(BLEND_MODE_WSR)
const int MODE = WSR;
#elif defined(BLEND_MODE_DUPLEX)
const int MODE = DUPLEX;
#elif defined(BLEND_MODE_STOCHASTIC)
const int MODE = STOCHASTIC;
#elif defined(BLEND_MODE_STOCHASTIC_POPFREE)
const int MODE = STOCHASTIC_POPFREE;
#elif defined(BLEND_MODE_EVAL3D)
const int MODE = EVAL3D;
#elif defined(BLEND_MODE_STOPTHEPOP)
const int MODE = STOPTHEPOP;
#endif
#if defined(GB_FAST) && GB_FAST
const bool FAST = true;
#else
const bool FAST = false;
#endif
#if defined(BLEND_MODE_EVAL3D) || defined(BLEND_MODE_STOPTHEPOP)
#define SORTED 1
#else
#define SORTED 0
#endif

layout(local_size_x = 16, local_size_y = 16) in;
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer TileVals { uint tile_vals[]; };  // splat ids, sorted by (tile, depth)
layout(std430, binding = 2) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 3) writeonly buffer EvalsOut { int evals_out[]; };
layout(std430, binding = 4) writeonly buffer WindowOut { vec2 window_out[]; };
layout(std430, binding = 5) buffer State { vec4 state[]; };  // BLEND_STATE_VEC4S per invocation
layout(std430, binding = 6) buffer Accum { vec4 accum[]; };  // BLEND_ACCUM_VEC4S per invocation
layout(std430, binding = 7) readonly buffer CellOf { int cell_of[]; };  // duplex: each splat's cell
layout(std430, binding = 8) readonly buffer Planes { vec4 planes[]; };  // stochastic_popfree: each splat's depth plane
layout(std430, binding = 9) readonly buffer Rays { vec4 rays[]; };  // eval3d, stopthepop: pack_ray per splat
layout(rgba32f, binding = 0) uniform writeonly image2D out_image;  // rgb, alpha = 1 - T; row 0 = image top

uniform ivec2 out_size;
uniform int supersample;
uniform ivec2 grid;  // render tiles
uniform vec3 background;
uniform int want_window;
uniform int subtile_begin;
uniform int subtile_end;
uniform int chunk_begin;
uniform int chunk_end;
uniform int load_state;
uniform int store_state;
uniform int load_accum;
uniform int store_accum;
uniform vec4 oit;  // OitParams: components OIT_* (interface.glsl)
uniform uvec2 stochastic;  // stochastic: seed, frame index (stochastic.h)
uniform int queue;  // stopthepop's K (0: the exact order)

shared Splat2D batch[256];
shared int done_count;
#if SUPERSAMPLED
shared vec4 sample_rgba[256];
shared int sample_evals[256];
shared vec2 sample_window[256];
#endif

// resort.glsl's list access (every variant links them; only the sorted ones call them)
Splat2D hier_splat(uint first, int i) {
    const uint at = SPLAT_VEC4S * tile_vals[first + uint(i)];
    return unpack_splat(splats[at], splats[at + 1u], splats[at + 2u], splats[at + 3u]);
}

RaySplat hier_ray(uint first, int i) {
    const uint at = RAY_VEC4S * tile_vals[first + uint(i)];
    return unpack_ray(rays[at], rays[at + 1u], rays[at + 2u], rays[at + 3u]);
}

#if SORTED
Splat2D list_splat(uint id) {
    const uint at = SPLAT_VEC4S * id;
    return unpack_splat(splats[at], splats[at + 1u], splats[at + 2u], splats[at + 3u]);
}

// Entry i of the list starting at `first` as a fragment at pix (sorted_fragment).
bool list_fragment(uint first, int i, vec2 pix, out Fragment f) {
    const uint id = tile_vals[first + uint(i)];
    const uint at = RAY_VEC4S * id;
    const RaySplat ray = unpack_ray(rays[at], rays[at + 1u], rays[at + 2u], rays[at + 3u]);
    f.entry = i;
    return sorted_fragment(MODE, list_splat(id), ray, pix.x, pix.y, f.alpha, f.depth);
}

vec3 list_color(uint first, Fragment f) { return list_splat(tile_vals[first + uint(f.entry)]).color; }

// One pixel (rpix; its render tile's first pixel: corner) of a per-pixel sorted mode (CUDA's sorted_kernel):
// stopthepop's hierarchy ending in a queue of K over the list in its tile order (the binning's), or (K = 0) the
// exact order by selection. Returns its evals (hier_walk's; the exact order: n).
int sorted_walk(uint first, int n, ivec2 rpix, ivec2 corner, inout float T, inout vec3 C) {
    const int K = MODE == EVAL3D ? 0 : queue;
    const vec2 pix = vec2(rpix) + 0.5;
    int ev = n;
    if (K > 0) {
        ev = hier_walk(first, n, K, corner.x, corner.y, rpix.x, rpix.y, T, C);
    } else {
        const float inf = uintBitsToFloat(0x7f800000u);
        Fragment last = Fragment(-inf, 0.0, -1);
        for (bool done = false; !done;) {
            Fragment best = Fragment(inf, 0.0, n), f;
            for (int i = 0; i < n; ++i)
                if (list_fragment(first, i, pix, f) && fragment_before(last, f) && fragment_before(f, best)) best = f;
            if (best.entry == n) break;
            done = blend_fragment(best, list_color(first, best), T, C);
            last = best;
        }
    }
    return ev;
}
#endif

void main() {
    const ivec2 l = ivec2(gl_LocalInvocationID.xy);
    const int lid = l.y * TILE + l.x;
    const ivec2 block = ivec2(gl_WorkGroupID.xy);
    const uint slot = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 256u + uint(lid);
    const ivec2 opix = block * TILE + l;
    const bool inside = all(lessThan(opix, out_size));
    const int N = supersample;
    const ivec2 render_size = out_size * N;
    vec4 acc = vec4(0.0);
    vec2 acc_window = vec2(0.0);
    int acc_evals = 0;
    if (load_accum != 0) {
        acc = accum[BLEND_ACCUM_VEC4S * slot];
        acc_window = accum[BLEND_ACCUM_VEC4S * slot + 1u].xy;
        acc_evals = floatBitsToInt(accum[BLEND_ACCUM_VEC4S * slot + 1u].z);
    }

    for (int sub = subtile_begin; sub < subtile_end; ++sub) {
        const ivec2 tile = block * N + ivec2(sub % N, sub / N);
        const ivec2 rpix = tile * TILE + l;
        bool done = !all(lessThan(rpix, render_size));
        uvec2 range = uvec2(0u);
        if (tile.x < grid.x && tile.y < grid.y) range = ranges[tile.y * grid.x + tile.x];
        const int n = int(range.y - range.x);
        const int begin = min(n, chunk_begin), end = min(n, chunk_end);
        const vec2 pix = vec2(rpix) + 0.5;
#if defined(BLEND_MODE_STOCHASTIC) || defined(BLEND_MODE_STOCHASTIC_POPFREE)
        const uint key =
            stochastic_sample_key(stochastic_frame_key(stochastic.x, stochastic.y), uint(rpix.x), uint(rpix.y));
#endif
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
        TransmittanceWindow win = TransmittanceWindow(1.0, pix, vec2(1.0, 1.0));
#elif defined(BLEND_MODE_WSR)
        WsrSums acc_wsr = WsrSums(vec3(0.0), 0.0);
#elif defined(BLEND_MODE_DUPLEX)
        DuplexState dst = DuplexState(1.0, 1.0, -1, 0.0, vec3(0.0));
#else
        float T = 1.0;
#endif
#if defined(BLEND_MODE_STOCHASTIC_POPFREE)
        float depth_key = uintBitsToFloat(0xff800000u);  // -inf: no fragment kept yet (stochastic.h)
#endif
        vec3 C = vec3(0.0);
        int evals = 0;
        if (load_state != 0) {
            const uint at = BLEND_STATE_VEC4S * slot;
            const vec4 s0 = state[at], s1 = state[at + 1u], s2 = state[at + 2u];
            C = s0.xyz;
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
            win = TransmittanceWindow(s0.w, s1.xy, s1.zw);
#elif defined(BLEND_MODE_WSR)
            acc_wsr = WsrSums(s0.xyz, s0.w);
#elif defined(BLEND_MODE_DUPLEX)
            dst = DuplexState(s0.w, s1.x, floatBitsToInt(s1.z), s1.y, s0.xyz);
#else
            T = s0.w;
#endif
            evals = floatBitsToInt(s2.x);
            done = s2.y != 0.0;
#if defined(BLEND_MODE_STOCHASTIC_POPFREE)
            depth_key = s2.z;
#endif
        }

        memoryBarrierShared();
        barrier();  // the previous tile's readers of done_count and the sample arrays are finished
        if (lid == 0) done_count = 0;
        memoryBarrierShared();
        barrier();
        if (done) atomicAdd(done_count, 1);
#if SORTED
        if (!done) evals = sorted_walk(range.x, n, rpix, tile * TILE, T, C);
#else
        for (int start = begin; start < end; start += 256) {
            memoryBarrierShared();
            barrier();  // everyone finished the previous batch (and its done_count increments)
            const bool all_done = done_count == 256;
            if (!all_done && start + lid < end) {
                const uint s = tile_vals[range.x + uint(start + lid)];
                const uint at = SPLAT_VEC4S * s;
                batch[lid] = unpack_splat(splats[at], splats[at + 1u], splats[at + 2u], splats[at + 3u]);
#if defined(BLEND_MODE_DUPLEX)
                batch[lid].cell = cell_of[s];
#endif
                batch[lid].id = int(s);
            }
            memoryBarrierShared();
            barrier();  // batch loaded; nobody changes done_count before everyone has read it
            if (all_done) break;
            if (!done) {
                const int count = min(256, end - start);
                for (int j = 0; j < count; ++j) {
                    ++evals;
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
                    const bool finished = blend_gaussian(batch[j], win, C, FAST);
#elif defined(BLEND_MODE_WSR)
                    const bool finished = blend_wsr(batch[j], pix, acc_wsr);
#elif defined(BLEND_MODE_DUPLEX)
                    const bool finished = blend_duplex(batch[j], pix, oit[OIT_ET_GRADE], dst);
#elif defined(BLEND_MODE_ANALYTIC)
                    const bool finished = blend_analytic(batch[j], pix, T, C);
#elif defined(BLEND_MODE_STOCHASTIC)
                    const bool finished = blend_stochastic(batch[j], pix, key, T, C);
#elif defined(BLEND_MODE_STOCHASTIC_POPFREE)
                    blend_stochastic_popfree(batch[j], planes[batch[j].id], pix, key, T, depth_key, C);
                    const bool finished = false;  // a nearer kept fragment may follow
#else
                    const bool finished = blend_scalar(batch[j], pix, T, C);
#endif
                    if (finished) {
                        done = true;
                        atomicAdd(done_count, 1);
                        break;
                    }
                }
            }
        }
#endif
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
        float T_final = win.T;
        const vec2 wh = win.wh;
        const vec2 wxy = win.xy;
#elif defined(BLEND_MODE_WSR)
        float T_final = acc_wsr.S;
        C = acc_wsr.C;
        const vec2 wh = vec2(1.0, 1.0);
        const vec2 wxy = pix;
#elif defined(BLEND_MODE_DUPLEX)
        float T_final = dst.T;
        C = dst.C;
        const vec2 wh = vec2(1.0, 1.0);
        const vec2 wxy = vec2(dst.T_cell, dst.S);
#else
        float T_final = T;
        const vec2 wh = vec2(1.0, 1.0);
        const vec2 wxy = pix;
#endif
        if (store_state != 0) {  // more of this tile's list follows in a later dispatch
            const uint at = BLEND_STATE_VEC4S * slot;
            state[at] = vec4(C, T_final);
#if defined(BLEND_MODE_DUPLEX)
            state[at + 1u] = vec4(wxy, intBitsToFloat(dst.cell), 0.0);
#else
            state[at + 1u] = vec4(wxy, wh);
#endif
#if defined(BLEND_MODE_STOCHASTIC_POPFREE)
            state[at + 2u] = vec4(intBitsToFloat(evals), done ? 1.0 : 0.0, depth_key, 0.0);
#else
            state[at + 2u] = vec4(intBitsToFloat(evals), done ? 1.0 : 0.0, 0.0, 0.0);
#endif
            continue;  // store_state is uniform, and the driver then gives this dispatch one render tile
        }
#if defined(BLEND_MODE_WSR)
        const PixelSums sums = PixelSums(acc_wsr.C, 1.0, acc_wsr.S);
#elif defined(BLEND_MODE_DUPLEX)
        const PixelSums sums = PixelSums(dst.C, dst.T, dst.S);
#else
        const PixelSums sums = PixelSums(C, T_final, 0.0);
#endif
        const vec4 rgba = resolve_pixel(MODE, sums, oit[OIT_WEIGHT_BACKGROUND], background);
#if SUPERSAMPLED
        sample_rgba[lid] = rgba;
        sample_evals[lid] = evals;
        sample_window[lid] = wh;
        memoryBarrierShared();
        barrier();
        if (inside) {  // add this tile's samples of my output pixel, rows then columns as box_downsample
            const ivec2 first = max(tile * TILE - opix * N, ivec2(0));
            const ivec2 last = min(tile * TILE + TILE - opix * N, ivec2(N));
            for (int sy = first.y; sy < last.y; ++sy) {
                for (int sx = first.x; sx < last.x; ++sx) {
                    const ivec2 q = opix * N + ivec2(sx, sy) - tile * TILE;
                    const int k = q.y * TILE + q.x;
                    acc += sample_rgba[k];
                    acc_evals += sample_evals[k];
                    acc_window += sample_window[k];
                }
            }
        }
#else
        acc = rgba;
        acc_evals = evals;
        acc_window = wh;
#endif
    }
    if (store_state != 0 || !inside) return;
    if (store_accum != 0) {  // more render tiles of this block follow in a later dispatch
        accum[BLEND_ACCUM_VEC4S * slot] = acc;
        accum[BLEND_ACCUM_VEC4S * slot + 1u] = vec4(acc_window, intBitsToFloat(acc_evals), 0.0);
        return;
    }
#if SUPERSAMPLED
    const float inv = 1.0 / float(N * N);
    acc *= inv;
    acc_window = acc_window * inv / float(N);  // in output pixels
#endif
    imageStore(out_image, opix, acc);
    const int p = opix.y * out_size.x + opix.x;
    evals_out[p] = acc_evals;
    if (want_window != 0) window_out[p] = acc_window;
}
