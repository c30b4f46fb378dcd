#version 450
// Irradiance cube E/pi from order-2 radiance SH: out = max(0, sum_k c_k Y_k(n)) per output texel, where the
// host has already scaled c by A_l / pi * window_l (probe/sh_project.py). One thread per output texel.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "probe_cube.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Coeffs { float c[]; };  // 9 x RGB, scaled
layout(std430, binding = 1) writeonly buffer Out { float outp[]; };
layout(push_constant) uniform P { uint m; uint clamp_negative; } p;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= 6u * p.m * p.m) return;
    uint face = idx / (p.m * p.m), rem = idx % (p.m * p.m);
    vec3 d = texel_dir(face, rem % p.m, rem / p.m, p.m);
    float b[9];
    b[0] = 0.28209479177387814;
    b[1] = -0.4886025119029199 * d.y; b[2] = 0.4886025119029199 * d.z; b[3] = -0.4886025119029199 * d.x;
    b[4] = 1.0925484305920792 * d.x * d.y; b[5] = -1.0925484305920792 * d.y * d.z;
    b[6] = 0.31539156525252005 * (2.0 * d.z * d.z - d.x * d.x - d.y * d.y);
    b[7] = -1.0925484305920792 * d.x * d.z; b[8] = 0.5462742152960396 * (d.x * d.x - d.y * d.y);
    vec3 e = vec3(0.0);
    for (int k = 0; k < 9; ++k) e += b[k] * vec3(c[k * 3], c[k * 3 + 1], c[k * 3 + 2]);
    if (p.clamp_negative != 0u) e = max(e, vec3(0.0));
    outp[idx * 3u] = e.r; outp[idx * 3u + 1u] = e.g; outp[idx * 3u + 2u] = e.b;
}
