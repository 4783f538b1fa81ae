// Stable LSD radix sort, pass step 2 of 2 (4-bit digits): each thread owns 8 consecutive keys of the block; a
// work-group scan of the per-thread digit counts gives every key its rank among the block's keys with the same
// digit, so equal digits keep their input order (stability is what makes the passes compose into a sort).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = 1) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = 4) readonly buffer Offsets { uint offsets[]; };  // scanned radix_count output

uniform uint n;
uniform uint shift;
uniform uint num_blocks;

shared uvec4 scan_lo[256];  // digits 0-7 and 8-15, two 16-bit counters per uint
shared uvec4 scan_hi[256];
shared uint digit_base[16];

void main() {
    const uint block = group_index();
    if (block >= num_blocks) return;
    const uint lid = gl_LocalInvocationID.x;
    if (lid < 16u) digit_base[lid] = offsets[lid * num_blocks + block];
    const uint base = block * 2048u + lid * 8u;
    uint key[8];
    uint val[8];
    uint c[8] = uint[](0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u);
    for (uint k = 0u; k < 8u; ++k) {
        const uint i = base + k;
        key[k] = 0u;
        val[k] = 0u;
        if (i < n) {
            key[k] = keys_in[i];
            val[k] = vals_in[i];
            const uint d = (key[k] >> shift) & 15u;
            c[d >> 1] += 1u << ((d & 1u) << 4);
        }
    }
    const uvec4 own_lo = uvec4(c[0], c[1], c[2], c[3]), own_hi = uvec4(c[4], c[5], c[6], c[7]);
    scan_lo[lid] = own_lo;
    scan_hi[lid] = own_hi;
    memoryBarrierShared();
    barrier();
    for (uint off = 1u; off < 256u; off <<= 1) {  // Hillis-Steele inclusive scan over the threads
        uvec4 add_lo = uvec4(0u), add_hi = uvec4(0u);
        if (lid >= off) {
            add_lo = scan_lo[lid - off];
            add_hi = scan_hi[lid - off];
        }
        memoryBarrierShared();
        barrier();
        scan_lo[lid] += add_lo;
        scan_hi[lid] += add_hi;
        memoryBarrierShared();
        barrier();
    }
    const uvec4 ex_lo = scan_lo[lid] - own_lo, ex_hi = scan_hi[lid] - own_hi;
    uint run[8] = uint[](ex_lo.x, ex_lo.y, ex_lo.z, ex_lo.w, ex_hi.x, ex_hi.y, ex_hi.z, ex_hi.w);
    for (uint k = 0u; k < 8u; ++k) {
        if (base + k < n) {
            const uint d = (key[k] >> shift) & 15u;
            const uint w = d >> 1, sh = (d & 1u) << 4;
            const uint p = digit_base[d] + ((run[w] >> sh) & 0xFFFFu);
            run[w] += 1u << sh;
            keys_out[p] = key[k];
            vals_out[p] = val[k];
        }
    }
}
