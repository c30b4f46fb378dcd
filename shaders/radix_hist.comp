#version 450
// Radix sort pass, step 1: per-block histogram of one 4-bit digit. hist is digit-major: hist[d * n_blocks + block],
// so one exclusive scan of it gives every (digit, block) its global output offset.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };
layout(std430, binding = 1) buffer Hist { uint hist[]; };
layout(std430, binding = 2) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key; } p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
shared uint h[16];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    if (lid < 16u) h[lid] = 0u;
    barrier();
    uint n = count[p.count_index];
    uint base = block * SORT_BLOCK;
    for (uint i = 0u; i < 16u; ++i) {
        uint idx = base + i * 256u + lid;
        if (idx < n) {
            uint k = keys[idx];
            if (!dropped(k)) atomicAdd(h[(k >> p.shift) & 15u], 1u);
        }
    }
    barrier();
    if (lid < 16u) hist[lid * p.n_blocks + block] = h[lid];
}
