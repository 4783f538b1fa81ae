// The (tile, splat) pairs in the order of `positions` (tile_keys.comp's sort): out[j] = in[positions[j]].
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Positions { uint positions[]; };
layout(std430, binding = 1) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = 2) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 3) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 4) writeonly buffer ValsOut { uint vals_out[]; };

uniform uint n;

void main() {
    const uint j = group_index() * 256u + gl_LocalInvocationID.x;
    if (j >= n) return;
    keys_out[j] = keys_in[positions[j]];
    vals_out[j] = vals_in[positions[j]];
}
