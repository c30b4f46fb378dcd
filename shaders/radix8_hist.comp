#version 450
// 8-bit radix pass, step 1: per-block histogram (blocks of block_rounds x 128 keys), digit-major: hist[d * n_blocks + block].
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 128) in;
layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };
layout(std430, binding = 1) buffer Hist { uint hist[]; };
layout(std430, binding = 2) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key;
    uint block_rounds;  // rounds of 128 keys per block: 32 (SORT_BLOCK keys), fewer for short sorts
} p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
shared uint h[256];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    h[lid] = 0u;
    h[lid + 128u] = 0u;
    barrier();
    uint n = count[p.count_index];
    uint base = block * p.block_rounds * 128u;
    for (uint i = 0u; i < p.block_rounds; ++i) {
        uint idx = base + i * 128u + lid;
        if (idx < n) {
            uint k = keys[idx];
            if (!dropped(k)) atomicAdd(h[(k >> p.shift) & 255u], 1u);
        }
    }
    barrier();
    hist[lid * p.n_blocks + block] = h[lid];
    hist[(lid + 128u) * p.n_blocks + block] = h[lid + 128u];
}
