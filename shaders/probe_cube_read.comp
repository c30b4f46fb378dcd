#version 450
// Reads an RGB cube of face size n by seamless bilinear lookup at the texel directions of an m x m cube:
// the last step of the box filter (the small cube read by normal). One thread per output texel.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(std430, binding = 0) readonly buffer Cube { float cube[]; };
#define PROBE_CUBE_BUFFER cube
#define PROBE_CUBE_OFFSET 0u
#include "probe_cube.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 1) writeonly buffer Out { float outp[]; };
layout(push_constant) uniform P { uint n; uint m; } p;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= 6u * p.m * p.m) return;
    uint face = idx / (p.m * p.m), rem = idx % (p.m * p.m);
    vec3 v = cube_bilinear(texel_dir(face, rem % p.m, rem / p.m, p.m), p.n);
    outp[idx * 3u] = v.r; outp[idx * 3u + 1u] = v.g; outp[idx * 3u + 2u] = v.b;
}
