#version 450
// Start and end of each tile's run in the tile-sorted instance list.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer InstKey { uint inst_key[]; };
layout(std430, binding = 1) readonly buffer Count { uint count[]; };
layout(std430, binding = 2) buffer Ranges { uvec2 ranges[]; };
void main() {
    uint j = linear_group() * 256u + gl_LocalInvocationID.x;
    uint m = count[0];
    if (j >= m) return;
    uint k = inst_key[j];
    if (j == 0u || inst_key[j - 1u] != k) ranges[k].x = j;
    if (j + 1u == m || inst_key[j + 1u] != k) ranges[k].y = j + 1u;
}
