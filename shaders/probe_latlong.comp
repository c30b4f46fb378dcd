#version 450
// RGB cube of face size n -> lat-long image (Blender's equirectangular mapping, core/cubemap.latlong_directions:
// u = 0.5 - atan2(y, x) / 2pi, v from the top = acos(z) / pi) by the seamless bilinear lookup, as
// probe/latlong.cube_to_latlong does in numpy. One thread per lat-long texel; output packed RGB, rows top first.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(std430, binding = 0) readonly buffer Cube { float cube[]; };
#define PROBE_CUBE_BUFFER cube
#define PROBE_CUBE_OFFSET 0u
#include "probe_cube.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 1) writeonly buffer Out { float outp[]; };
layout(push_constant) uniform P { uint n; uint width; uint height; } p;

const float PI = 3.14159265358979323846;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= p.width * p.height) return;
    uint x = idx % p.width, y = idx / p.width;
    float phi = (0.5 - (float(x) + 0.5) / float(p.width)) * 2.0 * PI;
    float theta = (float(y) + 0.5) / float(p.height) * PI;
    float st = sin(theta);
    vec3 v = cube_bilinear(vec3(st * cos(phi), st * sin(phi), cos(theta)), p.n);
    outp[idx * 3u] = v.r; outp[idx * 3u + 1u] = v.g; outp[idx * 3u + 2u] = v.b;
}
