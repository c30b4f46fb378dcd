#version 450
// Joins the chunk partials of gs_raster.comp front to back: (C, T, Z) o (C', T', Z') = (C + T C', T T', Z + T Z'),
// stopping where
// the transmittance has fallen below T_MIN as the unchunked raster would.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Partial { vec4 partial[]; };
layout(std430, binding = 1) writeonly buffer Image { vec4 image[]; };
layout(std430, binding = 2) readonly buffer PartialDepth { float partial_depth[]; };  // sum(T alpha z) per chunk
layout(std430, binding = 3) writeonly buffer Depth { float depth[]; };
layout(push_constant) uniform P { uint chunks; uint total_pixels; uint write_depth; } p;
const float T_MIN = 1e-4;

void main() {
    uint i = linear_group() * 256u + gl_LocalInvocationID.x;
    if (i >= p.total_pixels) return;
    vec3 c = vec3(0.0);
    float t = 1.0, z = 0.0;
    for (uint k = 0u; k < p.chunks && t >= T_MIN; ++k) {
        vec4 part = partial[k * p.total_pixels + i];
        c += t * part.rgb;
        if (p.write_depth != 0u) z += t * partial_depth[k * p.total_pixels + i];
        t *= part.w;
    }
    image[i] = vec4(c, 1.0 - t);
    if (p.write_depth != 0u) depth[i] = t < 1.0 ? z / (1.0 - t) : 0.0;
}
