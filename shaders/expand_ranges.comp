// Duplex: each tile's [start, end) in the list of (tile, cell) pairs becomes its range in the expanded splat list
// (through the exclusive scan of the pairs' splat counts; an end of n maps to the total).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer CellRanges { uvec2 cell_ranges[]; };
layout(std430, binding = 1) readonly buffer Offsets { uint offs[]; };
layout(std430, binding = 2) readonly buffer Totals { uint totals[]; };
layout(std430, binding = 3) writeonly buffer Ranges { uvec2 ranges[]; };

uniform uint num_tiles;
uniform uint n;  // cell pairs

uint at(uint k) { return k < n ? offs[k] : totals[TOTAL_EXPANDED]; }

void main() {
    const uint t = group_index() * 256u + gl_LocalInvocationID.x;
    if (t >= num_tiles) return;
    const uvec2 r = cell_ranges[t];
    ranges[t] = r.y > r.x ? uvec2(at(r.x), at(r.y)) : uvec2(0u);
}
