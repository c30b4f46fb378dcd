#version 450
// One (tile, splat) instance per tile each splat touches, written in depth order; a stable sort by tile then keeps
// front-to-back order inside every tile. A workgroup takes 256 depth-sorted splats, keeps their tile rectangles in
// shared memory, and spreads all their instances over its 256 threads, so one splat covering thousands of tiles
// does not leave the other threads idle. Instances past the capacity are dropped and reported.
// The tile rectangle bounds the splat's footprint; a tile inside it that the footprint misses (a long diagonal
// splat's corners) gets the key `n_tiles`, one past the last tile, so the sort moves it out of every tile's run.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Views { View views[]; };
layout(std430, binding = 1) readonly buffer DepthKey { uint depth_key[]; };
layout(std430, binding = 2) readonly buffer DepthVal { uint depth_val[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 4) readonly buffer Total { uint total[]; };
layout(std430, binding = 5) writeonly buffer InstKey { uint inst_key[]; };
layout(std430, binding = 6) writeonly buffer InstVal { uint inst_val[]; };
layout(std430, binding = 7) writeonly buffer Count { uint count[]; };  // [0] kept instances, [1] all instances
layout(std430, binding = 8) readonly buffer Prepared { vec4 prepared[]; };
layout(std430, binding = 9) readonly buffer Rects { uvec2 rects[]; };  // from gs_preprocess
layout(push_constant) uniform P { uint n; uint capacity; uint n_views; uint n_tiles; } p;

shared uvec2 s_rect[256u * MAX_VIEWS];  // (x0 | y0 << 16, x1 | y1 << 16) in tiles; x0 == x1 when untouched
shared uint s_start[256];
shared uint s_splat[256];
shared vec4 s_g0[256], s_g1[256];  // footprint quadric G (symmetric) and a flag: see footprint_quadric()

// The rays d inside the splat's footprint satisfy m(d) <= c, i.e. d^T G d <= 0 with
// G = W^T ((|o'|^2 - c) I - o' o'^T) W (splat_math.py: m = |o' x Wd|^2 / |Wd|^2). c is inflated a little so float
// rounding never culls a tile that the raster would light. For splats tiny against their distance the quadric
// loses precision; they cover a tile or two anyway, so they keep their rectangle (flag 1).
void footprint_quadric(uint i, float cutoff, out vec4 g0, out vec4 g1) {
    vec4 a = prepared[PREP * i], b = prepared[PREP * i + 1u], e = prepared[PREP * i + 2u];
    vec3 ol = vec3(a.w, b.w, e.w);
    float c = cutoff * 1.02 + 1e-3;
    float oo = dot(ol, ol);
    if (oo > 1e4 * c) { g0 = vec4(0.0); g1 = vec4(0.0, 0.0, 1.0, 0.0); return; }
    mat3 wt = mat3(a.xyz, b.xyz, e.xyz);  // columns = rows of W, i.e. W^T
    mat3 k = mat3(oo - c) - outerProduct(ol, ol);
    mat3 g = wt * k * transpose(wt);
    g0 = vec4(g[0][0], g[0][1], g[0][2], g[1][1]);
    g1 = vec4(g[1][2], g[2][2], 0.0, 0.0);
}

float qmin_1d(float a, float b, float c, float lo, float hi) {  // min of a x^2 + 2 b x + c over [lo, hi]
    float x = a > 0.0 ? clamp(-b / a, lo, hi) : lo;
    float v = (a * x + 2.0 * b) * x + c;
    return a > 0.0 ? v : min(v, (a * hi + 2.0 * b) * hi + c);
}

// Does the footprint reach a pixel centre of tile (tx, ty) of view v?
bool tile_touched(uint s, View vw, uint tx, uint ty) {
    vec4 g0 = s_g0[s], g1 = s_g1[s];
    if (g1.z != 0.0) return true;
    mat3 g = mat3(g0.x, g0.y, g0.z, g0.y, g0.w, g1.x, g0.z, g1.x, g1.y);
    vec3 r = vw.right_tanx.xyz, dn = vw.down_tany.xyz, f = vw.fwd.xyz;
    vec3 gr = g * r, gd = g * dn, gf = g * f;
    float A = dot(r, gr), B = dot(dn, gd), C = dot(r, gd), D = dot(r, gf), E = dot(dn, gf), F = dot(f, gf);
    float w = float(vw.dims.x), h = float(vw.dims.y);
    uint px0 = tx * TILE, py0 = ty * TILE;
    uint px1 = min(px0 + TILE, vw.dims.x) - 1u, py1 = min(py0 + TILE, vw.dims.y) - 1u;
    float s0 = ((float(px0) + 0.5) / w * 2.0 - 1.0) * vw.right_tanx.w, s1 = ((float(px1) + 0.5) / w * 2.0 - 1.0) * vw.right_tanx.w;
    float t0 = ((float(py0) + 0.5) / h * 2.0 - 1.0) * vw.down_tany.w, t1 = ((float(py1) + 0.5) / h * 2.0 - 1.0) * vw.down_tany.w;
    // Q(s, t) = A s^2 + B t^2 + 2 C s t + 2 D s + 2 E t + F; its minimum over the rectangle is on an edge or at
    // the interior critical point.
    float m = min(min(qmin_1d(B, C * s0 + E, (A * s0 + 2.0 * D) * s0 + F, t0, t1),
                      qmin_1d(B, C * s1 + E, (A * s1 + 2.0 * D) * s1 + F, t0, t1)),
                  min(qmin_1d(A, C * t0 + D, (B * t0 + 2.0 * E) * t0 + F, s0, s1),
                      qmin_1d(A, C * t1 + D, (B * t1 + 2.0 * E) * t1 + F, s0, s1)));
    float det = A * B - C * C;
    if (A > 0.0 && det > 0.0) {
        float ss = (C * E - B * D) / det, tt = (C * D - A * E) / det;
        if (ss >= s0 && ss <= s1 && tt >= t0 && tt <= t1) m = min(m, ((A * ss + 2.0 * C * tt + 2.0 * D) * ss) + (B * tt + 2.0 * E) * tt + F);
    }
    return m <= 0.0;
}

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
        footprint_quadric(i, prepared[PREP * i + 4u].x, s_g0[t], s_g1[t]);
        for (uint v = 0u; v < p.n_views; ++v) s_rect[t * MAX_VIEWS + v] = rects[i * MAX_VIEWS + v];
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
                    uint tx = x0 + r % w, ty = y0 + r / w;
                    bool hit = tile_touched(lo, views[v], tx, ty);
                    inst_key[q] = hit ? views[v].dims.w + ty * views[v].dims.z + tx : p.n_tiles;
                    inst_val[q] = s_splat[lo];
                }
                break;
            }
            r -= w * h;
        }
    }
}
