#version 450
// Order-2 SH projection of an RGB radiance cube, first stage of a parallel reduction: each workgroup sums
// L * Y_k * dOmega over a strided share of the texels and writes its 27 partial sums (9 coeffs x RGB) to
// partial[group * 27 + k * 3 + c]; the host adds the few group partials in float64 (probe/gpu_filters.py).
// Basis: core/sh.py (3DGS signs, l <= 2); solid angles: core/cubemap.texel_solid_angles, uploaded.
// Several probes' cubes one after another (a batch, gpu_filters.FilterPlan): workgroup z is the probe.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "probe_cube.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Cube { float cube[]; };
layout(std430, binding = 1) readonly buffer Omega { float omega[]; };  // N*N texel solid angles
layout(std430, binding = 2) writeonly buffer Partial { float partial[]; };
layout(push_constant) uniform P { uint n; uint n_groups; } p;
shared float red[256 * 27];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint g = linear_group();
    float acc[27];
    for (int k = 0; k < 27; ++k) acc[k] = 0.0;
    uint total = 6u * p.n * p.n, base = gl_WorkGroupID.z * total;
    for (uint idx = g * 256u + lid; idx < total; idx += p.n_groups * 256u) {
        uint face = idx / (p.n * p.n), rem = idx % (p.n * p.n), j = rem / p.n, i = rem % p.n;
        vec3 d = texel_dir(face, i, j, p.n);
        uint o = (base + idx) * 3u;
        vec3 L = vec3(cube[o], cube[o + 1u], cube[o + 2u]) * omega[rem];
        float b[9];
        b[0] = 0.28209479177387814;
        b[1] = -0.4886025119029199 * d.y; b[2] = 0.4886025119029199 * d.z; b[3] = -0.4886025119029199 * d.x;
        b[4] = 1.0925484305920792 * d.x * d.y; b[5] = -1.0925484305920792 * d.y * d.z;
        b[6] = 0.31539156525252005 * (2.0 * d.z * d.z - d.x * d.x - d.y * d.y);
        b[7] = -1.0925484305920792 * d.x * d.z; b[8] = 0.5462742152960396 * (d.x * d.x - d.y * d.y);
        for (int k = 0; k < 9; ++k) {
            acc[k * 3] += b[k] * L.r; acc[k * 3 + 1] += b[k] * L.g; acc[k * 3 + 2] += b[k] * L.b;
        }
    }
    for (int k = 0; k < 27; ++k) red[lid * 27u + uint(k)] = acc[k];
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lid < stride)
            for (uint k = 0u; k < 27u; ++k) red[lid * 27u + k] += red[(lid + stride) * 27u + k];
        barrier();
    }
    if (lid < 27u) partial[(gl_WorkGroupID.z * p.n_groups + g) * 27u + lid] = red[lid];
}
