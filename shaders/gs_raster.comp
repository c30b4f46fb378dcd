#version 450
// One workgroup per 16x16 tile of any view: front-to-back compositing of the tile's splats, each evaluated along
// the pixel's ray, in batches staged through shared memory; stops when every pixel of the tile is opaque.
// Small images have few tiles, too few to fill a GPU: then each tile's list is cut into `chunks` consecutive
// pieces composited by separate workgroups into (colour, transmittance) partials, which gs_merge.comp joins in
// order (front-to-back compositing is associative).
// Several probes (SplatRenderer.render_probes): workgroup z is the probe; total_tiles counts one probe's tiles and
// total_pixels every probe's pixels; probe k's tiles and pixels follow probe k-1's.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"
layout(local_size_x = 16, local_size_y = 16) in;
layout(std430, binding = 0) readonly buffer Views { View views[]; };
layout(std430, binding = 1) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 2) readonly buffer InstVal { uint inst_val[]; };
layout(std430, binding = 3) readonly buffer Prepared { vec4 prepared[]; };
layout(std430, binding = 4) writeonly buffer Image { vec4 image[]; };  // chunks > 1: partials, chunk-major
// Depth: the alpha-weighted sum of each contribution's distance along the view axis, sum(T alpha z); divided by
// the coverage it is the expected depth of what the pixel shows. It composes across chunks like the colour.
layout(std430, binding = 5) writeonly buffer Depth { float depth[]; };
// write_depth 0: nothing is written to Depth (bound to a placeholder), so colour-only frames skip that traffic.
layout(push_constant) uniform P { uint n_views; uint total_tiles; uint chunks; uint total_pixels; uint write_depth; } p;

const float ALPHA_MAX = 0.99, T_MIN = 1e-4;
shared vec4 s_w0[256], s_w1[256], s_w2[256], s_col[256];
shared float s_cut[256];
shared uint s_done;

void main() {
    uint wg = linear_group();
    if (wg >= p.total_tiles * p.chunks) return;  // uniform per workgroup
    uint g = wg % p.total_tiles, chunk = wg / p.total_tiles;
    uint probe = gl_WorkGroupID.z;
    uint v = 0u;
    for (uint k = 1u; k < p.n_views; ++k) if (g >= views[k].dims.w) v = k;
    View vw = views[v];
    View last = views[p.n_views - 1u];
    uint probe_pixels = last.extra.x + last.dims.x * last.dims.y;
    uint local_tile = g - vw.dims.w;
    uint px = (local_tile % vw.dims.z) * TILE + gl_LocalInvocationID.x;
    uint py = (local_tile / vw.dims.z) * TILE + gl_LocalInvocationID.y;
    bool inside = px < vw.dims.x && py < vw.dims.y;
    float s = ((float(px) + 0.5) / float(vw.dims.x) * 2.0 - 1.0) * vw.right_tanx.w;
    float t = ((float(py) + 0.5) / float(vw.dims.y) * 2.0 - 1.0) * vw.down_tany.w;
    vec3 d = vw.fwd.xyz + s * vw.right_tanx.xyz + t * vw.down_tany.xyz;

    uvec2 whole = ranges[probe * p.total_tiles + g];
    uint len = whole.y - whole.x;
    uint q = len / p.chunks, rem = len % p.chunks;  // chunk c starts at c*q + min(c, rem): no overflow
    uvec2 range = whole.x + uvec2(chunk * q + min(chunk, rem), (chunk + 1u) * q + min(chunk + 1u, rem));
    uint lid = gl_LocalInvocationIndex;
    bool done = !inside;
    vec3 color = vec3(0.0);
    float T = 1.0, zsum = 0.0;
    for (uint start = range.x; start < range.y; start += 256u) {
        barrier();
        if (lid == 0u) s_done = 0u;
        barrier();
        if (done) atomicAdd(s_done, 1u);
        uint j = start + lid;
        if (j < range.y) {
            uint i = inst_val[j];
            s_w0[lid] = prepared[PREP * i]; s_w1[lid] = prepared[PREP * i + 1u];
            s_w2[lid] = prepared[PREP * i + 2u]; s_col[lid] = prepared[PREP * i + 3u];
            s_cut[lid] = prepared[PREP * i + 4u].x;
        }
        barrier();
        if (s_done == 256u) break;
        uint batch = min(256u, range.y - start);
        for (uint k = 0u; k < batch && !done; ++k) {
            vec3 ol = vec3(s_w0[k].w, s_w1[k].w, s_w2[k].w);
            vec3 dl = vec3(dot(s_w0[k].xyz, d), dot(s_w1[k].xyz, d), dot(s_w2[k].xyz, d));
            if (dot(ol, dl) >= 0.0) continue;  // the closest approach lies behind the origin
            vec3 cr = cross(ol, dl);
            float cc = dot(cr, cr), dd = dot(dl, dl);
            if (cc > s_cut[k] * dd) continue;  // outside the footprint (3DGS: alpha < 1/255); m = cc / dd
            float alpha = min(ALPHA_MAX, s_col[k].w * exp(-0.5 * cc / dd));
            color += T * alpha * s_col[k].rgb;
            if (p.write_depth != 0u) zsum += T * alpha * (-dot(ol, dl) / dd);  // closest approach along d; d's forward part is 1
            T *= 1.0 - alpha;
            // Unlike 3DGS, the splat that crosses T_MIN is kept: the rule then composes chunk by chunk, and a
            // nearly opaque last splat does not leave up to 1% of transmittance behind.
            if (T < T_MIN) { done = true; break; }
        }
    }
    uint pixel = probe * probe_pixels + vw.extra.x + py * vw.dims.x + px;
    if (inside) {
        if (p.chunks == 1u) {
            image[pixel] = vec4(color, 1.0 - T);
            if (p.write_depth != 0u) depth[pixel] = T < 1.0 ? zsum / (1.0 - T) : 0.0;
        } else {
            image[chunk * p.total_pixels + pixel] = vec4(color, T);
            if (p.write_depth != 0u) depth[chunk * p.total_pixels + pixel] = zsum;
        }
    }
}
