#version 450
// One (tile, splat) instance per tile each splat touches, written in depth order; a stable sort by tile then
// keeps front-to-back order inside every tile. Instances past the capacity are dropped and reported.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer PosOp { vec4 pos_op[]; };
layout(std430, binding = 1) readonly buffer Scale { vec4 scale[]; };
layout(std430, binding = 2) readonly buffer Rot { vec4 rot[]; };
layout(std430, binding = 3) readonly buffer Views { View views[]; };
layout(std430, binding = 4) readonly buffer DepthKey { uint depth_key[]; };
layout(std430, binding = 5) readonly buffer DepthVal { uint depth_val[]; };
layout(std430, binding = 6) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 7) readonly buffer Total { uint total[]; };
layout(std430, binding = 8) writeonly buffer InstKey { uint inst_key[]; };
layout(std430, binding = 9) writeonly buffer InstVal { uint inst_val[]; };
layout(std430, binding = 10) writeonly buffer Count { uint count[]; };  // [0] kept instances, [1] all instances
layout(push_constant) uniform P { vec3 origin; uint n; float pixel_angle; uint capacity; uint n_views; } p;

void main() {
    uint j = linear_group() * 256u + gl_LocalInvocationID.x;
    if (j == 0u) { count[0] = min(total[0], p.capacity); count[1] = total[0]; }
    if (j >= p.n || depth_key[j] == 0xFFFFFFFFu) return;
    uint i = depth_val[j];
    uint off = offsets[j];
    vec4 po = pos_op[i];
    vec3 mu = po.xyz - p.origin;
    float dist = uintBitsToFloat(depth_key[j]);
    mat3 cov = cut_covariance(quat_to_mat(rot[i]), dilated_scale2(scale[i].xyz, dist, p.pixel_angle),
                              2.0 * log(255.0 * po.w));
    for (uint v = 0u; v < p.n_views; ++v) {
        uvec4 rc;
        if (!view_rect(views[v], mu, cov, rc)) continue;
        uint base = views[v].dims.w, tx = views[v].dims.z;
        for (uint y = rc.y; y < rc.w; ++y) {
            for (uint x = rc.x; x < rc.z; ++x) {
                if (off < p.capacity) { inst_key[off] = base + y * tx + x; inst_val[off] = i; }
                off++;
            }
        }
    }
}
