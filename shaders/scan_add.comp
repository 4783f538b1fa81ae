// Exclusive prefix sum, level 2: add each block's offset (the scanned block totals) to its 1024 elements.
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) buffer Data { uint data[]; };
layout(std430, binding = 1) readonly buffer Sums { uint sums[]; };

uniform uint n;
uniform uint num_blocks;

void main() {
    const uint block = group_index();
    if (block >= num_blocks) return;
    const uint add = sums[block];
    const uint base = block * 1024u + gl_LocalInvocationID.x;
    for (uint k = 0u; k < 4u; ++k) {
        const uint i = base + k * 256u;
        if (i < n) data[i] += add;
    }
}
