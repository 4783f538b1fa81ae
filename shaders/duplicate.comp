// One (tile, splat) pair per tile a splat touches, written in depth order (duplicateWithKeys). A stable radix sort
// by tile then leaves every tile's list ordered by (depth, splat index), as the CPU driver's per-tile sort.
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Vals { uint vals[]; };
layout(std430, binding = 1) readonly buffer Rects { ivec4 rects[]; };
layout(std430, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 3) writeonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 4) writeonly buffer TileVals { uint tile_vals[]; };

uniform uint n;
uniform int grid_x;
uniform uint capacity;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= n) return;
    const uint s = vals[i];
    const ivec4 r = rects[s];
    uint o = offsets[i];
    for (int ty = r.y; ty < r.w; ++ty) {
        for (int tx = r.x; tx < r.z; ++tx) {
            if (o < capacity) {
                tile_keys[o] = uint(ty * grid_x + tx);
                tile_vals[o] = s;
            }
            ++o;
        }
    }
}
