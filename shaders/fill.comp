// data[0..n) = value (clears per-frame buffers on the GPU, without a CPU upload or a sync).
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) writeonly buffer Data { uint data[]; };

uniform uint n;
uniform uint value;

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i < n) data[i] = value;
}
