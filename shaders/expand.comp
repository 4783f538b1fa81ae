// Duplex: every (tile, cell) pair of the tile-sorted list becomes its cell's visible splats, written from the
// pair's exclusive-scan offset; `counts` first receives each pair's splat count (mode 0), then the expansion runs on
// the scanned offsets (mode 1).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer PairCells { uint pair_cells[]; };  // cell of each tile-sorted pair
layout(std430, binding = 1) readonly buffer CellOut { vec4 cell_out[]; };  // .w: visible member count
layout(std430, binding = 2) readonly buffer Offsets { int cell_offsets[]; };
layout(std430, binding = 3) readonly buffer Vis { uint vis[]; };
layout(std430, binding = 4) buffer Counts { uint counts[]; };
layout(std430, binding = 5) writeonly buffer Splats { uint splat_list[]; };

uniform uint n;
uniform int mode;

void main() {
    const uint k = group_index() * 256u + gl_LocalInvocationID.x;
    if (k >= n) return;
    const uint c = pair_cells[k];
    const uint count = floatBitsToUint(cell_out[c].w);
    if (mode == 0) {
        counts[k] = count;
        return;
    }
    const uint out0 = counts[k], in0 = uint(cell_offsets[c]);
    for (uint j = 0u; j < count; ++j) splat_list[out0 + j] = vis[in0 + j];
}
