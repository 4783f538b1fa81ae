// Duplex: visible cells in cell-index order (positions from the exclusive scan of their flags): key = depth bits
// minus the smallest visible cell depth's bits, value = cell index.
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer CellOut { vec4 cell_out[]; };
layout(std430, binding = 1) readonly buffer CellRects { ivec4 cell_rects[]; };
layout(std430, binding = 2) readonly buffer Pos { uint pos[]; };
layout(std430, binding = 3) readonly buffer Totals { uint totals[]; };
layout(std430, binding = 4) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 5) writeonly buffer Vals { uint vals[]; };

uniform uint num_cells;

void main() {
    const uint c = group_index() * 256u + gl_LocalInvocationID.x;
    if (c >= num_cells) return;
    const ivec4 r = cell_rects[c];
    if (r.z <= r.x) return;
    const uint p = pos[c];
    keys[p] = floatBitsToUint(cell_out[c].z) - totals[TOTAL_CELL_DEPTH_MIN];
    vals[p] = c;
}
