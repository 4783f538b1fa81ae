// Survivors in splat-index order (positions from the exclusive scan of the flags): sort key = depth bits minus the
// smallest visible depth's bits (same order, fewer radix passes), value = splat index.
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer Rects { ivec4 rects[]; };
layout(std430, binding = 2) readonly buffer Pos { uint pos[]; };
layout(std430, binding = 3) readonly buffer Totals { uint totals[]; };
layout(std430, binding = 4) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 5) writeonly buffer Vals { uint vals[]; };

uniform uint num_splats;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= num_splats) return;
    const ivec4 r = rects[i];
    if (r.z <= r.x) return;
    const uint p = pos[i];
    keys[p] = floatBitsToUint(splats[SPLAT_VEC4S * i].z) - totals[TOTAL_DEPTH_MIN];
    vals[p] = i;
}
