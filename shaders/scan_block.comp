#version 450
// Exclusive prefix sum of 1024-element blocks, in place; each block's total goes to sums[block].
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) buffer Data { uint data[]; };
layout(std430, binding = 1) buffer Sums { uint sums[]; };
layout(push_constant) uniform P { uint n; } p;
shared uint partial[256];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint base = linear_group() * SCAN_BLOCK + lid * 4u;
    uint v[4];
    uint run = 0u;
    for (int i = 0; i < 4; ++i) {
        uint idx = base + uint(i);
        v[i] = idx < p.n ? data[idx] : 0u;
        run += v[i];
    }
    partial[lid] = run;
    barrier();
    // Hillis-Steele inclusive scan of the 256 per-thread totals.
    for (uint off = 1u; off < 256u; off <<= 1) {
        uint add = lid >= off ? partial[lid - off] : 0u;
        barrier();
        partial[lid] += add;
        barrier();
    }
    uint excl = partial[lid] - run;
    for (int i = 0; i < 4; ++i) {
        uint idx = base + uint(i);
        if (idx < p.n) data[idx] = excl;
        excl += v[i];
    }
    if (lid == 255u) sums[linear_group()] = partial[255];
}
