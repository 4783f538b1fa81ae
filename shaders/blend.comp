// Blend: one work group per 16 x 16 block of output pixels, one invocation per pixel. With N x N supersampling the
// block covers N x N render tiles (the render resolution is N times the output's, tiles are 16 render pixels),
// which the group blends one after another and box-averages in shared memory, like the CPU driver's
// render-then-box_downsample. A tile's depth-sorted splats go through shared memory in batches of 256; the loop
// over batches stops when every pixel of the tile has terminated.
// Compiled once per mode and sampling: the driver defines BLEND_MODE_<MODE> (SCALAR, MIP, ANALYTIC or
// GAUSSIAN_BLENDING) and SUPERSAMPLED (0 or 1).
#include "common.glsl"
#include "mathf.glsl"
#include "blend.glsl"
#include "kernel.glsl"

layout(local_size_x = 16, local_size_y = 16) in;
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer TileVals { uint tile_vals[]; };  // splat ids, sorted by (tile, depth)
layout(std430, binding = 2) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 3) writeonly buffer EvalsOut { int evals_out[]; };
layout(std430, binding = 4) writeonly buffer WindowOut { vec2 window_out[]; };
layout(rgba32f, binding = 0) uniform writeonly image2D out_image;  // rgb, alpha = 1 - T; row 0 = image top

uniform ivec2 out_size;
uniform int supersample;
uniform ivec2 grid;  // render tiles
uniform vec3 background;
uniform int want_window;

shared Splat2D batch[256];
shared int done_count;
#if SUPERSAMPLED
shared vec4 sample_rgba[256];
shared int sample_evals[256];
shared vec2 sample_window[256];
#endif

void main() {
    const ivec2 l = ivec2(gl_LocalInvocationID.xy);
    const int lid = l.y * TILE + l.x;
    const ivec2 block = ivec2(gl_WorkGroupID.xy);
    const ivec2 opix = block * TILE + l;
    const bool inside = all(lessThan(opix, out_size));
    const int N = supersample;
    const ivec2 render_size = out_size * N;
    vec4 acc = vec4(0.0);
    vec2 acc_window = vec2(0.0);
    int acc_evals = 0;

    for (int ty = 0; ty < N; ++ty) {
        for (int tx = 0; tx < N; ++tx) {
            const ivec2 tile = block * N + ivec2(tx, ty);
            const ivec2 rpix = tile * TILE + l;
            bool done = !all(lessThan(rpix, render_size));
            uvec2 range = uvec2(0u);
            if (tile.x < grid.x && tile.y < grid.y) range = ranges[tile.y * grid.x + tile.x];
            const int n = int(range.y - range.x);
            const vec2 pix = vec2(rpix) + 0.5;
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
            TransmittanceWindow win = TransmittanceWindow(1.0, pix, vec2(1.0, 1.0));
#else
            float T = 1.0;
#endif
            vec3 C = vec3(0.0);
            int evals = 0;

            memoryBarrierShared();
            barrier();  // the previous tile's readers of done_count and the sample arrays are finished
            if (lid == 0) done_count = 0;
            memoryBarrierShared();
            barrier();
            if (done) atomicAdd(done_count, 1);
            for (int start = 0; start < n; start += 256) {
                memoryBarrierShared();
                barrier();  // everyone finished the previous batch (and its done_count increments)
                const bool all_done = done_count == 256;
                if (!all_done && start + lid < n) {
                    const uint s = tile_vals[range.x + uint(start + lid)];
                    batch[lid] = unpack_splat(splats[4u * s], splats[4u * s + 1u], splats[4u * s + 2u],
                                              splats[4u * s + 3u]);
                }
                memoryBarrierShared();
                barrier();  // batch loaded; nobody changes done_count before everyone has read it
                if (all_done) break;
                if (!done) {
                    const int count = min(256, n - start);
                    for (int j = 0; j < count; ++j) {
                        ++evals;
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
                        const bool finished = blend_gaussian(batch[j], win, C);
#elif defined(BLEND_MODE_ANALYTIC)
                        const bool finished = blend_analytic(batch[j], pix, T, C);
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
#if defined(BLEND_MODE_GAUSSIAN_BLENDING)
            const float T_final = win.T;
            const vec2 wh = win.wh;
#else
            const float T_final = T;
            const vec2 wh = vec2(1.0, 1.0);
#endif
            const vec4 rgba = vec4(C + T_final * background, 1.0 - T_final);
#if SUPERSAMPLED
            sample_rgba[lid] = rgba;
            sample_evals[lid] = evals;
            sample_window[lid] = wh;
            memoryBarrierShared();
            barrier();
            if (inside) {  // add this tile's samples of my output pixel, rows then columns as box_downsample
                for (int sy = 0; sy < N; ++sy) {
                    for (int sx = 0; sx < N; ++sx) {
                        const ivec2 q = opix * N + ivec2(sx, sy) - tile * TILE;
                        if (all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, ivec2(TILE)))) {
                            const int k = q.y * TILE + q.x;
                            acc += sample_rgba[k];
                            acc_evals += sample_evals[k];
                            acc_window += sample_window[k];
                        }
                    }
                }
            }
#else
            acc = rgba;
            acc_evals = evals;
            acc_window = wh;
#endif
        }
    }
    if (!inside) return;
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
