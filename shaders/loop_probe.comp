// How many loop iterations one invocation may run: llvmpipe (Mesa 22) silently ends every loop once an
// invocation has run 65535 iterations in total; GPUs have no such cap. The driver plans the blend around it.
layout(local_size_x = 1) in;
layout(std430, binding = 0) writeonly buffer Out { uint count; };

uniform uint n;

void main() {
    uint c = 0u;
    for (uint i = 0u; i < n; ++i) c += 1u;
    count = c;
}
