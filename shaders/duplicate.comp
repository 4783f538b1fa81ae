// One (tile, splat) pair per tile a splat touches, written in depth order (duplicateWithKeys). A stable radix sort
// by tile then leaves every tile's list ordered by (depth, splat index), as the CPU driver's per-tile sort.
// One invocation per pair: it finds its splat by binary search in the exclusive scan of the splats' tile counts
// (so a splat covering thousands of tiles is spread over thousands of invocations, not one long loop).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Vals { uint vals[]; };  // splat ids sorted by (depth, index)
layout(std430, binding = 1) readonly buffer Rects { ivec4 rects[]; };
layout(std430, binding = 2) readonly buffer Offsets { uint offsets[]; };  // first pair of each sorted splat
layout(std430, binding = 3) writeonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 4) writeonly buffer TileVals { uint tile_vals[]; };

uniform uint num_pairs;
uniform uint num_splats;  // visible splats (length of vals and offsets)
uniform int grid_x;

void main() {
    const uint k = group_index() * 256u + gl_LocalInvocationID.x;
    if (k >= num_pairs) return;
    uint lo = 0u, hi = num_splats;  // offsets[lo] <= k < offsets[hi] (offsets[num_splats] = num_pairs)
    while (hi - lo > 1u) {
        const uint mid = (lo + hi) >> 1;
        if (offsets[mid] <= k)
            lo = mid;
        else
            hi = mid;
    }
    const uint s = vals[lo];
    const ivec4 r = rects[s];
    const int local = int(k - offsets[lo]), w = r.z - r.x;
    tile_keys[k] = uint((r.y + local / w) * grid_x + r.x + local % w);
    tile_vals[k] = s;
}
