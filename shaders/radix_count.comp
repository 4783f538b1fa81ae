// Stable LSD radix sort, pass step 1 of 2 (4-bit digits): per block of 2048 keys, how many keys have each digit.
// counts[digit * num_blocks + block], so the exclusive scan of `counts` gives every (digit, block) its first
// output position.
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };
layout(std430, binding = 1) writeonly buffer Counts { uint counts[]; };

uniform uint n;
uniform uint shift;
uniform uint num_blocks;

shared uint hist[8];  // 16 digit counters, two 16-bit fields per uint (a block has <= 2048 keys)

void main() {
    const uint block = group_index();
    if (block >= num_blocks) return;
    const uint lid = gl_LocalInvocationID.x;
    if (lid < 8u) hist[lid] = 0u;
    memoryBarrierShared();
    barrier();
    uint c[8] = uint[](0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u);
    const uint base = block * 2048u + lid;
    for (uint k = 0u; k < 8u; ++k) {
        const uint i = base + k * 256u;
        if (i < n) {
            const uint d = (keys[i] >> shift) & 15u;
            c[d >> 1] += 1u << ((d & 1u) << 4);
        }
    }
    for (uint w = 0u; w < 8u; ++w)
        if (c[w] != 0u) atomicAdd(hist[w], c[w]);
    memoryBarrierShared();
    barrier();
    if (lid < 16u) counts[lid * num_blocks + block] = (hist[lid >> 1] >> ((lid & 1u) << 4)) & 0xFFFFu;
}
