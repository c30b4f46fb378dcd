#version 450
// Adds each block's scanned offset to its 1024 elements (second half of the multi-level scan).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) buffer Data { uint data[]; };
layout(std430, binding = 1) readonly buffer Sums { uint sums[]; };
layout(push_constant) uniform P { uint n; } p;

void main() {
    uint g = linear_group();
    uint add = sums[g];
    uint base = g * SCAN_BLOCK + gl_LocalInvocationID.x;
    for (uint i = 0u; i < 4u; ++i) {
        uint idx = base + i * 256u;
        if (idx < p.n) data[idx] += add;
    }
}
