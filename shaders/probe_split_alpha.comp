#version 450
// A rendered frame (premultiplied RGBA per pixel, the six cube faces in order) to the packed RGB cube the probe
// filters read, on the GPU: the render-to-filter boundary needs no host round trip. As probe/sampling.split_alpha,
// holes stay black (the colour is already premultiplied) and the hole fraction of the sphere by solid angle,
// sum((1 - clamp(alpha)) * dOmega) / 4pi, is reduced per workgroup into partial[group]; the host adds those few.
// Several probes' cubes one after another (a batch, gpu_filters.FilterPlan): workgroup z is the probe.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Frame { vec4 frame[]; };
layout(std430, binding = 1) readonly buffer Omega { float omega[]; };  // N*N texel solid angles
layout(std430, binding = 2) writeonly buffer Cube { float cube[]; };
layout(std430, binding = 3) writeonly buffer Partial { float partial[]; };
layout(push_constant) uniform P { uint n; uint n_groups; } p;
shared float red[256];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint g = linear_group();
    uint total = 6u * p.n * p.n, base = gl_WorkGroupID.z * total;
    float hole = 0.0;
    for (uint idx = g * 256u + lid; idx < total; idx += p.n_groups * 256u) {
        vec4 c = frame[base + idx];
        uint o = (base + idx) * 3u;
        cube[o] = c.r; cube[o + 1u] = c.g; cube[o + 2u] = c.b;
        hole += (1.0 - clamp(c.a, 0.0, 1.0)) * omega[idx % (p.n * p.n)];
    }
    red[lid] = hole;
    barrier();
    for (uint s = 128u; s > 0u; s >>= 1) {
        if (lid < s) red[lid] += red[lid + s];
        barrier();
    }
    if (lid == 0u) partial[gl_WorkGroupID.z * p.n_groups + g] = red[0];
}
