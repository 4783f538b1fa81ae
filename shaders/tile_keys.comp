// stopthepop:K's tile stage (resort.h: tile_depth_key): for every (tile, splat) pair of the tile-sorted lists, the
// splat's key in that tile as uint bits (the key is >= 0, so the bits sort as the floats) and the pair's position.
// A stable radix sort by the key, a gather (gather_pairs.comp) and a stable sort by tile then order every tile's list
// by (key, centre-depth order), as the CPU's tile_depth_order.
#include "common.glsl"
#include "mathf.glsl"
#include "ray3d.glsl"
#include "resort_key.glsl"
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer Rays { vec4 rays[]; };
layout(std430, binding = 2) readonly buffer TileKeys { uint tile_keys[]; };  // each pair's tile
layout(std430, binding = 3) readonly buffer TileVals { uint tile_vals[]; };  // each pair's splat
layout(std430, binding = 4) writeonly buffer DepthKeys { uint depth_keys[]; };
layout(std430, binding = 5) writeonly buffer Positions { uint positions[]; };

uniform uint n;
uniform int grid_x;
uniform vec4 cam_f;  // fx, fy, cx, cy of the render resolution

void main() {
    const uint k = group_index() * 256u + gl_LocalInvocationID.x;
    if (k >= n) return;
    const uint s = tile_vals[k], t = tile_keys[k];
    const uint at = SPLAT_VEC4S * s, ra = RAY_VEC4S * s;
    const Splat2D splat = unpack_splat(splats[at], splats[at + 1u], splats[at + 2u], splats[at + 3u]);
    const RaySplat ray = unpack_ray(rays[ra], rays[ra + 1u], rays[ra + 2u], rays[ra + 3u]);
    const float x0 = float(int(t) % grid_x * TILE) + 0.5, y0 = float(int(t) / grid_x * TILE) + 0.5;
    depth_keys[k] = floatBitsToUint(tile_depth_key(splat, ray, x0, y0, cam_f.z, cam_f.w, cam_f.x, cam_f.y));
    positions[k] = k;
}
