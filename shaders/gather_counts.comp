// Tiles touched by each visible splat, in depth order (the input of the scan that places its tile-splat pairs).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Vals { uint vals[]; };  // splat ids sorted by (depth, index)
layout(std430, binding = 1) readonly buffer Rects { ivec4 rects[]; };
layout(std430, binding = 2) writeonly buffer Counts { uint counts[]; };

uniform uint n;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= n) return;
    const ivec4 r = rects[vals[i]];
    counts[i] = uint((r.z - r.x) * (r.w - r.y));
}
