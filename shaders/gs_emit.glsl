// One (tile, splat) instance per tile each splat touches, written in depth order; a stable sort by tile then keeps
// front-to-back order inside every tile. One thread per instance: the thread finds the splat owning its slot by a
// binary search of the depth-ordered prefix sums, so the work is even however unevenly the tiles are spread (the
// nearest splats, which cover whole faces, all sit at the front of the depth order); with EMIT_PER_SPLAT (CPU
// devices) one thread per splat writes its own slots instead (main below). Instances past the capacity are dropped
// and reported.
// The tile rectangle bounds the splat's footprint; a tile inside it that the footprint misses (a long diagonal
// splat's corners) gets the key `n_tiles`, one past the last tile, so the sort moves it out of every tile's run.
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
layout(std430, binding = 10) readonly buffer Owners { uint owners[]; };  // from gs_emit_owners
layout(push_constant) uniform P { uint n; uint capacity; uint n_views; uint n_tiles; } p;

// The rays d inside the splat's footprint satisfy m(d) <= c, i.e. d^T G d <= 0 with
// G = W^T ((|o'|^2 - c) I - o' o'^T) W (splat_math.py: m = |o' x Wd|^2 / |Wd|^2). c is inflated a little so float
// rounding never culls a tile that the raster would light. For splats tiny against their distance the quadric
// loses precision; they cover a tile or two anyway, so they keep their whole rectangle (returns false).
bool footprint_quadric(uint i, out mat3 g) {
    vec4 a = prepared[PREP * i], b = prepared[PREP * i + 1u], e = prepared[PREP * i + 2u];
    vec3 ol = vec3(a.w, b.w, e.w);
    float c = prepared[PREP * i + 4u].x * 1.02 + 1e-3;
    float oo = dot(ol, ol);
    if (oo > 1e4 * c) return false;
    mat3 wt = mat3(a.xyz, b.xyz, e.xyz);  // columns = rows of W, i.e. W^T
    g = wt * (mat3(oo - c) - outerProduct(ol, ol)) * transpose(wt);
    return true;
}

float qmin_1d(float a, float b, float c, float lo, float hi) {  // min of a x^2 + 2 b x + c over [lo, hi]
    float x = a > 0.0 ? clamp(-b / a, lo, hi) : lo;
    float v = (a * x + 2.0 * b) * x + c;
    return a > 0.0 ? v : min(v, (a * hi + 2.0 * b) * hi + c);
}

// Does the footprint reach a pixel centre of tile (tx, ty) of view v?
bool tile_touched(mat3 g, View vw, uint tx, uint ty) {
    vec3 r = vw.right_tanx.xyz, dn = vw.down_tany.xyz, f = vw.fwd.xyz;
    vec3 gr = g * r, gd = g * dn, gf = g * f;
    float A = dot(r, gr), B = dot(dn, gd), C = dot(r, gd), D = dot(r, gf), E = dot(dn, gf), F = dot(f, gf);
    uint px0 = tx * TILE, py0 = ty * TILE;
    uint px1 = min(px0 + TILE, vw.dims.x) - 1u, py1 = min(py0 + TILE, vw.dims.y) - 1u;
    float s0 = view_s(vw, px0), s1 = view_s(vw, px1), t0 = view_t(vw, py0), t1 = view_t(vw, py1);
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

#ifdef EMIT_PER_SPLAT
// One thread per splat (in depth order), writing its own slots offsets[j] .. offsets[j + 1] - 1: the same slots and
// keys as one thread per slot, with no search and the footprint's quadric taken once. For CPU devices, which run a
// workgroup's lanes one after another (renderer.py EMIT_PER_SPLAT says why): on a GPU the nearest splats' many
// tiles would hold their warps back.
void main() {
    uint j = linear_group() * 256u + gl_LocalInvocationID.x;
    uint all_instances = total[0], used = min(all_instances, p.capacity);
    if (j == 0u) { count[0] = used; count[1] = all_instances; }
    if (j >= p.n) return;
    uint q = offsets[j], end = min(j + 1u < p.n ? offsets[j + 1u] : all_instances, used);
    if (q >= end) return;
    uint i = depth_val[j];
    mat3 g;
    bool whole = !footprint_quadric(i, g);
    uint probe_base = uint(prepared[PREP * i + 4u].y);  // the pair's probe's first tile
    for (uint v = 0u; v < p.n_views && q < end; ++v) {
        uvec2 pr = rects[i * MAX_VIEWS + v];
        uint x0 = pr.x & 0xFFFFu, y0 = pr.x >> 16, w = (pr.y & 0xFFFFu) - x0, h = (pr.y >> 16) - y0;
        for (uint r = 0u; r < w * h && q < end; ++r, ++q) {
            uint tx = x0 + r % w, ty = y0 + r / w;
            bool hit = whole || tile_touched(g, views[v], tx, ty);
            inst_key[q] = hit ? probe_base + views[v].dims.w + ty * views[v].dims.z + tx : p.n_tiles;
            inst_val[q] = i;
        }
    }
}
#else
void main() {
    uint q = linear_group() * 256u + gl_LocalInvocationID.x;
    uint all_instances = total[0], used = min(all_instances, p.capacity);
    if (q == 0u) { count[0] = used; count[1] = all_instances; }
    if (q >= used) return;
    // the owner of slot q: the last splat (in depth order) whose first slot is <= q; empty splats share a start
    // with their successor and so are never the last. It lies between this block's owner and the next block's
    // (gs_emit_owners.comp).
    uint block = q / 256u;
    uint lo = owners[block], hi = (block + 1u) * 256u < used ? owners[block + 1u] : p.n - 1u;
    while (lo < hi) {
        uint mid = (lo + hi + 1u) >> 1;
        if (offsets[mid] <= q) lo = mid; else hi = mid - 1u;
    }
    uint i = depth_val[lo];
    uint r = q - offsets[lo];
    for (uint v = 0u; v < p.n_views; ++v) {
        uvec2 pr = rects[i * MAX_VIEWS + v];
        uint x0 = pr.x & 0xFFFFu, y0 = pr.x >> 16, w = (pr.y & 0xFFFFu) - x0, h = (pr.y >> 16) - y0;
        if (r < w * h) {
            uint tx = x0 + r % w, ty = y0 + r / w;
            mat3 g;
            bool hit = !footprint_quadric(i, g) || tile_touched(g, views[v], tx, ty);
            uint probe_base = uint(prepared[PREP * i + 4u].y);  // the pair's probe's first tile
            inst_key[q] = hit ? probe_base + views[v].dims.w + ty * views[v].dims.z + tx : p.n_tiles;
            inst_val[q] = i;
            return;
        }
        r -= w * h;
    }
}
#endif
