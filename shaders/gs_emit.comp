#version 450
// One (tile, splat) instance per tile each splat touches, written in depth order; a stable sort by tile then keeps
// front-to-back order inside every tile. A workgroup takes 256 depth-sorted splats, keeps their tile rectangles in
// shared memory, and spreads all their instances over its 256 threads, so one splat covering thousands of tiles
// does not leave the other threads idle. Instances past the capacity are dropped and reported.
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

const uint MAX_VIEWS = 6u;
shared uvec2 s_rect[256u * MAX_VIEWS];  // (x0 | y0 << 16, x1 | y1 << 16) in tiles; x0 == x1 when untouched
shared uint s_start[256];
shared uint s_splat[256];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint j0 = linear_group() * 256u;
    uint j = j0 + t;
    uint all_instances = total[0];
    if (j == 0u) { count[0] = min(all_instances, p.capacity); count[1] = all_instances; }
    if (j0 >= p.n) return;  // uniform per workgroup
    s_start[t] = j < p.n ? offsets[j] : all_instances;
    for (uint v = 0u; v < MAX_VIEWS; ++v) s_rect[t * MAX_VIEWS + v] = uvec2(0u);
    if (j < p.n && depth_key[j] != 0xFFFFFFFFu) {
        uint i = depth_val[j];
        s_splat[t] = i;
        vec4 po = pos_op[i];
        vec3 mu = po.xyz - p.origin;
        float dist = uintBitsToFloat(depth_key[j]);
        mat3 cov = cut_covariance(quat_to_mat(rot[i]), dilated_scale2(scale[i].xyz, dist, p.pixel_angle),
                                  2.0 * log(255.0 * po.w));
        for (uint v = 0u; v < p.n_views; ++v) {
            uvec4 rc;
            if (view_rect(views[v], mu, cov, rc)) s_rect[t * MAX_VIEWS + v] = uvec2(rc.x | (rc.y << 16), rc.z | (rc.w << 16));
        }
    }
    barrier();
    uint end = j0 + 256u < p.n ? offsets[j0 + 256u] : all_instances;
    for (uint q = s_start[0] + t; q < end; q += 256u) {
        // the splat owning instance q: the last one whose first instance is <= q (empty ranges share a start)
        uint lo = 0u, hi = 255u;
        while (lo < hi) {
            uint mid = (lo + hi + 1u) >> 1;
            if (s_start[mid] <= q) lo = mid; else hi = mid - 1u;
        }
        uint r = q - s_start[lo];
        for (uint v = 0u; v < p.n_views; ++v) {
            uvec2 pr = s_rect[lo * MAX_VIEWS + v];
            uint x0 = pr.x & 0xFFFFu, y0 = pr.x >> 16, w = (pr.y & 0xFFFFu) - x0, h = (pr.y >> 16) - y0;
            if (r < w * h) {
                if (q < p.capacity) {
                    inst_key[q] = views[v].dims.w + (y0 + r / w) * views[v].dims.z + x0 + r % w;
                    inst_val[q] = s_splat[lo];
                }
                break;
            }
            r -= w * h;
        }
    }
}
