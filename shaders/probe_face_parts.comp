#version 450
// The change between two RGBA cubes of one size (rgb of a - b) as six one-face cubes, probe f holding face f's
// change and black elsewhere (alpha 1), for the exact filter of six probes to split it into each face's part of the
// irradiance (probe/reference.py exact_irradiance_parts; core/bake.py irradiance_parts builds the same on the host).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer A { vec4 a[]; };
layout(std430, binding = 1) readonly buffer B { vec4 b[]; };
layout(std430, binding = 2) writeonly buffer Out { vec4 outv[]; };  // 6 probes x 6 faces x n*n
layout(push_constant) uniform P { uint n; } p;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    uint cube = 6u * p.n * p.n;
    if (idx >= 6u * cube) return;
    uint probe = idx / cube, texel = idx % cube;
    outv[idx] = texel / (p.n * p.n) == probe ? vec4(a[texel].rgb - b[texel].rgb, 1.0) : vec4(0.0, 0.0, 0.0, 1.0);
}
