// [start, end) of every tile's run in the sorted pair list (identifyTileRanges); tiles without pairs keep (0, 0).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 1) buffer Ranges { uvec2 ranges[]; };

uniform uint n;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= n) return;
    const uint t = tile_keys[i];
    if (i == 0u || tile_keys[i - 1u] != t) ranges[t].x = i;
    if (i == n - 1u || tile_keys[i + 1u] != t) ranges[t].y = i + 1u;
}
