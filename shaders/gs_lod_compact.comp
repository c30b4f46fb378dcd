#version 450
// A level of detail's drawn nodes, in storage order (the upload's tie order), packed to the front for the depth
// sort: `live` holds the exclusive prefix sum of gs_preprocess's flags, so the order (and which of two equal keys
// comes first) is the same as without a level of detail.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer DepthKey { uint depth_key[]; };
layout(std430, binding = 1) readonly buffer Live { uint live[]; };
layout(std430, binding = 2) writeonly buffer SortKey { uint sort_key[]; };
layout(std430, binding = 3) writeonly buffer SortVal { uint sort_val[]; };
layout(push_constant) uniform P { uint n; } p;
void main() {
    uint i = linear_group() * 256u + gl_LocalInvocationID.x;
    if (i >= p.n) return;
    uint k = depth_key[i];
    if (k == 0xFFFFFFFFu) return;
    sort_key[live[i]] = k;
    sort_val[live[i]] = i;
}
