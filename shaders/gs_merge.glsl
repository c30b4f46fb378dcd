// Joins the chunk partials of gs_raster.glsl front to back: (C, T, Z) o (C', T', Z') = (C + T C', T T', Z + T Z'),
// stopping where the transmittance has fallen below T_MIN as the unchunked raster would.
// MERGE_CUT (gs_merge_cut, after the *_cut rasters): each chunk's contributions fell in FRONT or BEHIND by the
// pixel's cut, and each layer is composited among its own, so each layer's partials join by the same rule, in chunk
// order (a chunk's contributions all follow the previous chunk's): FRONT ends where it is opaque, and so does the
// whole pixel, as the unchunked raster ends; BEHIND stops taking chunks once what it lets through FRONT is below
// T_MIN. PartialDepth holds
// two sums a pixel there (front, behind), and Depth gets the depth of FRONT over BEHIND.
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Partial { vec4 partial[]; };
layout(std430, binding = 1) writeonly buffer Image { vec4 image[]; };
layout(std430, binding = 2) readonly buffer PartialDepth { float partial_depth[]; };  // sum(T alpha z) per chunk
layout(std430, binding = 3) writeonly buffer Depth { float depth[]; };
// MERGE_CUT: gs_merge_cut.comp declares PartialBehind (binding 4) and Behind (binding 5)
layout(push_constant) uniform P { uint chunks; uint total_pixels; uint write_depth; } p;
const float T_MIN = 1e-4;

void main() {
    uint i = linear_group() * 256u + gl_LocalInvocationID.x;
    if (i >= p.total_pixels) return;
    vec3 c = vec3(0.0);
    float t = 1.0, z = 0.0;
#ifdef MERGE_CUT
    vec3 bc = vec3(0.0);
    float bt = 1.0, bz = 0.0;
    for (uint k = 0u; k < p.chunks && t >= T_MIN; ++k) {
        uint j = k * p.total_pixels + i;
        if (t * bt >= T_MIN) {  // BEHIND's chunk while BEHIND shows through FRONT (the raster's rule, chunk by chunk)
            vec4 bpart = partial_behind[j];
            bc += bt * bpart.rgb;
            if (p.write_depth != 0u) bz += bt * partial_depth[2u * j + 1u];
            bt *= bpart.w;
        }
        vec4 part = partial[j];
        c += t * part.rgb;
        if (p.write_depth != 0u) z += t * partial_depth[2u * j];
        t *= part.w;
    }
    image[i] = vec4(c, 1.0 - t);
    behind[i] = vec4(bc, 1.0 - bt);
    float tt = t * bt;
    if (p.write_depth != 0u) depth[i] = tt < 1.0 ? (z + t * bz) / (1.0 - tt) : 0.0;
#else
    for (uint k = 0u; k < p.chunks && t >= T_MIN; ++k) {
        vec4 part = partial[k * p.total_pixels + i];
        c += t * part.rgb;
        if (p.write_depth != 0u) z += t * partial_depth[k * p.total_pixels + i];
        t *= part.w;
    }
    image[i] = vec4(c, 1.0 - t);
    if (p.write_depth != 0u) depth[i] = t < 1.0 ? z / (1.0 - t) : 0.0;
#endif
}
