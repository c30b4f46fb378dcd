#version 450
// One workgroup per 16x16 tile of any view: front-to-back compositing of the tile's splats, each evaluated along
// the pixel's ray, in batches staged through shared memory; stops when every pixel of the tile is opaque.
// Small images have few tiles, too few to fill a GPU: then each tile's list is cut into `chunks` consecutive
// pieces composited by separate workgroups into (colour, transmittance) partials, which gs_merge.comp joins in
// order (front-to-back compositing is associative).
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
shared uint s_box[256];  // the splat's pixels in this tile: x0 | x1 << 4 | y0 << 8 | y1 << 12 (x0 > x1: none)
shared uint s_done;

const uint WHOLE_TILE = 0xF0F0u;

// Bounds of d.x over the directions d within the cone of axis u (unit) and sine sa around it, for a unit x.
vec2 cone_dot(float ux, float ca, float sa) {
    return vec2(min(ux, ux * ca) - sa, max(ux, ux * ca) + sa);
}

// Pixel centres [lo, hi] of one axis (pixels p0 .. p0 + 15 of a view n pixels wide) whose tangent lies in
// [a, b], as tile-local indices clamped to 0..15 (lo > hi: none).
uvec2 pixel_span(float a, float b, float tan_half, float n, float p0) {
    float x0 = (a / tan_half + 1.0) * 0.5 * n - 0.5 - p0, x1 = (b / tan_half + 1.0) * 0.5 * n - 0.5 - p0;
    x0 = clamp(ceil(x0 - 0.01), 0.0, 16.0);  // a hundredth of a pixel of slack for rounding
    x1 = clamp(floor(x1 + 0.01), -1.0, 15.0);
    return x0 > x1 ? uvec2(15u, 0u) : uvec2(x0, x1);
}

// Which pixels of this tile (whose first pixel is (p0x, p0y) of view vw) the splat can reach: the cone stored by
// gs_preprocess (prepared[4].yzw = u / sin), with its sine widened by 1% so rounding never loses a pixel that
// passes the footprint test below. The whole tile where there is no cone or it reaches behind the view plane.
uint tile_box(vec3 q, View vw, float p0x, float p0y) {
    float qq = dot(q, q);
    if (qq == 0.0) return WHOLE_TILE;
    float inv = inversesqrt(qq);
    vec3 u = q * inv;
    float sa = min(inv * 1.01 + 1e-6, 1.0), ca = sqrt(1.0 - sa * sa);
    vec2 df = cone_dot(dot(u, vw.fwd.xyz), ca, sa);
    if (df.x <= 1e-3) return WHOLE_TILE;
    vec2 dr = cone_dot(dot(u, vw.right_tanx.xyz), ca, sa), dd = cone_dot(dot(u, vw.down_tany.xyz), ca, sa);
    // tangent = (d . axis) / (d . fwd) with d . fwd > 0: interval division
    vec2 s = vec2(min(dr.x / df.x, dr.x / df.y), max(dr.y / df.x, dr.y / df.y));
    vec2 t = vec2(min(dd.x / df.x, dd.x / df.y), max(dd.y / df.x, dd.y / df.y));
    uvec2 bx = pixel_span(s.x, s.y, vw.right_tanx.w, float(vw.dims.x), p0x);
    uvec2 by = pixel_span(t.x, t.y, vw.down_tany.w, float(vw.dims.y), p0y);
    return bx.x | (bx.y << 4) | (by.x << 8) | (by.y << 12);
}

void main() {
    uint wg = linear_group();
    if (wg >= p.total_tiles * p.chunks) return;  // uniform per workgroup
    uint g = wg % p.total_tiles, chunk = wg / p.total_tiles;
    uint v = 0u;
    for (uint k = 1u; k < p.n_views; ++k) if (g >= views[k].dims.w) v = k;
    View vw = views[v];
    uint local_tile = g - vw.dims.w;
    uint p0x = (local_tile % vw.dims.z) * TILE, p0y = (local_tile / vw.dims.z) * TILE;
    uint lx = gl_LocalInvocationID.x, ly = gl_LocalInvocationID.y;
    uint px = p0x + lx, py = p0y + ly;
    bool inside = px < vw.dims.x && py < vw.dims.y;
    float s = ((float(px) + 0.5) / float(vw.dims.x) * 2.0 - 1.0) * vw.right_tanx.w;
    float t = ((float(py) + 0.5) / float(vw.dims.y) * 2.0 - 1.0) * vw.down_tany.w;
    vec3 d = vw.fwd.xyz + s * vw.right_tanx.xyz + t * vw.down_tany.xyz;

    uvec2 whole = ranges[g];
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
            vec4 c = prepared[PREP * i + 4u];
            s_cut[lid] = c.x;
            s_box[lid] = tile_box(c.yzw, vw, float(p0x), float(p0y));
        }
        barrier();
        if (s_done == 256u) break;
        uint batch = min(256u, range.y - start);
        for (uint k = 0u; k < batch && !done; ++k) {
            uint b = s_box[k];
            if (lx < (b & 15u) || lx > ((b >> 4) & 15u) || ly < ((b >> 8) & 15u) || ly > (b >> 12)) continue;
            vec3 ol = vec3(s_w0[k].w, s_w1[k].w, s_w2[k].w);
            vec3 dl = vec3(dot(s_w0[k].xyz, d), dot(s_w1[k].xyz, d), dot(s_w2[k].xyz, d));
            if (dot(ol, dl) >= 0.0) continue;  // the closest approach lies behind the origin
            vec3 cr = cross(ol, dl);
            float m = dot(cr, cr) / dot(dl, dl);
            if (m > s_cut[k]) continue;  // outside the footprint (3DGS: alpha < 1/255)
            float alpha = min(ALPHA_MAX, s_col[k].w * exp(-0.5 * m));
            color += T * alpha * s_col[k].rgb;
            if (p.write_depth != 0u) zsum += T * alpha * (-dot(ol, dl) / dot(dl, dl));  // closest approach along d
            T *= 1.0 - alpha;
            // Unlike 3DGS, the splat that crosses T_MIN is kept: the rule then composes chunk by chunk, and a
            // nearly opaque last splat does not leave up to 1% of transmittance behind.
            if (T < T_MIN) { done = true; break; }
        }
    }
    uint pixel = vw.extra.x + py * vw.dims.x + px;
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
