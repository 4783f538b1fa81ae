// Longest tile list (only needed on drivers that cap loop iterations, to plan the blend dispatches).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 1) buffer Totals { uint totals[]; };

uniform uint n;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i < n) atomicMax(totals[TOTAL_MAX_LIST], ranges[i].y - ranges[i].x);
}
