#version 450
// One 2x2 solid-angle-weighted downsampling step of an RGB cube (probe/box.py::downsample_cube):
// parent = sum(child * dOmega_child) / sum(dOmega_child). One thread per parent texel.
// Several probes' cubes one after another (a batch, gpu_filters.FilterPlan): workgroup z is the probe.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Src { float src[]; };
layout(std430, binding = 1) readonly buffer Omega { float omega[]; };  // child level's N*N solid angles
layout(std430, binding = 2) writeonly buffer Dst { float dst[]; };
layout(push_constant) uniform P { uint n; } p;  // child face size (even)

void main() {
    uint h = p.n / 2u;
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= 6u * h * h) return;
    uint probe = gl_WorkGroupID.z;
    uint face = idx / (h * h), rem = idx % (h * h), J = rem / h, I = rem % h;
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (uint dj = 0u; dj < 2u; ++dj)
        for (uint di = 0u; di < 2u; ++di) {
            uint j = 2u * J + dj, i = 2u * I + di;
            float w = omega[j * p.n + i];
            uint s = (((probe * 6u + face) * p.n + j) * p.n + i) * 3u;
            sum += w * vec3(src[s], src[s + 1u], src[s + 2u]);
            wsum += w;
        }
    vec3 v = sum / wsum;
    uint d = (probe * 6u * h * h + idx) * 3u;
    dst[d] = v.r; dst[d + 1u] = v.g; dst[d + 2u] = v.b;
}
