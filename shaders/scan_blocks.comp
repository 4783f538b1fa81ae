// Exclusive prefix sum, level 1 of 2 per recursion step: each group scans 1024 uints in place and writes its block
// total to `sums`. A single-block scan writes the grand total to totals[total_slot] (when >= 0).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) buffer Data { uint data[]; };
layout(std430, binding = 1) writeonly buffer Sums { uint sums[]; };
layout(std430, binding = 2) writeonly buffer Totals { uint totals[]; };

uniform uint n;
uniform uint num_blocks;
uniform int total_slot;

shared uint partial[256];

void main() {
    const uint block = group_index();
    if (block >= num_blocks) return;
    const uint lid = gl_LocalInvocationID.x;
    const uint base = block * 1024u + lid * 4u;
    uint v[4];
    uint own = 0u;
    for (uint k = 0u; k < 4u; ++k) {
        v[k] = base + k < n ? data[base + k] : 0u;
        own += v[k];
    }
    partial[lid] = own;
    memoryBarrierShared();
    barrier();
    for (uint off = 1u; off < 256u; off <<= 1) {  // Hillis-Steele inclusive scan of the per-thread sums
        const uint add = lid >= off ? partial[lid - off] : 0u;
        memoryBarrierShared();
        barrier();
        partial[lid] += add;
        memoryBarrierShared();
        barrier();
    }
    uint run = partial[lid] - own;
    for (uint k = 0u; k < 4u; ++k) {
        if (base + k < n) data[base + k] = run;
        run += v[k];
    }
    if (lid == 255u) {
        sums[block] = partial[255];
        if (total_slot >= 0 && num_blocks == 1u) totals[total_slot] = partial[255];
    }
}
