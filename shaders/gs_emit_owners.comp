#version 450
// Where each block of 256 instance slots begins: owners[b] = the splat (a depth-ordered index) whose instances hold
// slot b * 256. gs_emit's threads (one workgroup per block) then search only between their block's owner and the
// next block's, a few dozen splats, not all of them: the full search is a chain of ~23 dependent loads at 6M
// splats, and emit's time was that latency. A splat spanning many blocks writes each of them.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Offsets { uint offsets[]; };  // exclusive prefix sum of the counts
layout(std430, binding = 1) readonly buffer Total { uint total[]; };
layout(std430, binding = 2) writeonly buffer Owners { uint owners[]; };
layout(push_constant) uniform P { uint n; uint capacity; } p;

void main() {
    uint j = linear_group() * 256u + gl_LocalInvocationID.x;
    if (j >= p.n) return;
    uint used = min(total[0], p.capacity);
    uint start = offsets[j];
    uint end = min(j + 1u < p.n ? offsets[j + 1u] : total[0], used);
    for (uint b = (start + 255u) / 256u; b * 256u < end; ++b) owners[b] = j;
}
