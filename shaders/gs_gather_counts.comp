#version 450
// Tile counts in depth order, so that their prefix sum places each splat's instances in front-to-back order.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer DepthKey { uint depth_key[]; };
layout(std430, binding = 1) readonly buffer DepthVal { uint depth_val[]; };
layout(std430, binding = 2) readonly buffer TileCount { uint tile_count[]; };
layout(std430, binding = 3) writeonly buffer Offsets { uint offsets[]; };
// How many depth-sorted entries are valid (a level of detail's cut is counted on the GPU); those after add nothing.
layout(std430, binding = 4) readonly buffer Count { uint count[]; };
layout(push_constant) uniform P { uint n; uint count_index; } p;
void main() {
    uint j = linear_group() * 256u + gl_LocalInvocationID.x;
    if (j >= p.n) return;
    offsets[j] = (j >= count[p.count_index] || depth_key[j] == 0xFFFFFFFFu) ? 0u : tile_count[depth_val[j]];
}
