// One workgroup per 16x16 tile of any view: front-to-back compositing of the tile's splats, each evaluated along
// the pixel's ray, in batches staged through shared memory; stops when every pixel of the tile is opaque.
// Small images have few tiles, too few to fill a GPU: then each tile's list is cut into `chunks` consecutive
// pieces composited by separate workgroups into (colour, transmittance) partials, which gs_merge.comp joins in
// order (front-to-back compositing is associative).
// Several probes (SplatRenderer.render_probes): workgroup z is the probe; total_tiles counts one probe's tiles and
// total_pixels every probe's pixels; probe k's tiles and pixels follow probe k-1's.
// RASTER_CUT (the *_cut kernels; camera frames given a depth cut, SplatRenderer.render(cut=...)): each pixel has a
// cut, the distance along the view axis of the mesh surface it sees (+inf: none). A contribution whose distance
// along the view axis (its closest approach: the z the depth output averages) is below the cut goes to the FRONT
// layer (Image), any other to the BEHIND layer (Behind), each composited front to back among its own
// contributions, so that a caller puts the mesh between them: front + (1 - front.a) (mesh + (1 - mesh.a) behind).
// The pixel ends once FRONT is opaque (nothing after it shows, transmittance < T_MIN as without a cut); BEHIND stops
// taking contributions once what it lets through is below T_MIN behind FRONT (T bT < T_MIN: the plain kernel's rule
// for the whole blend, with the mesh transparent), FRONT going on. With cut = +inf everywhere FRONT is the plain
// kernel's image bit for bit and BEHIND is 0; with cut = 0, BEHIND is that image and FRONT is 0.
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
// [3]: the most pairs one workgroup (a tile's chunk) went through, for the renderer's loop limit (LOOP_PAIRS: lavapipe
// ends a shader's loops after 65,535 iterations in all, and would leave the rest of a deeper list out).
layout(std430, binding = 6) buffer Count { uint count[]; };
#ifdef RASTER_CUT
// The *_cut.comp files declare Cut (binding 7: per pixel of the frame) and Behind (binding 8: BEHIND as Image holds
// FRONT; with chunks > 1 both hold partials, and Depth holds two sums a pixel, front and behind)
#define CUT_PARAMS , float cut_z, float cut_far, inout vec3 bcolor, inout float bT, inout float bzsum, inout bool skip
#define CUT_ARGS , cut_z, cut_far, bcolor, bT, bzsum, skip
#define AND_NOT_SKIPPED && !skip
#else
#define AND_NOT_SKIPPED
#define CUT_PARAMS
#define CUT_ARGS
#endif
// write_depth 0: nothing is written to Depth (bound to a placeholder), so colour-only frames skip that traffic.
// plane_forms 0: every pair takes the ray test (plane_form; the conic kernel has none).
layout(push_constant) uniform P {
    uint n_views; uint total_tiles; uint chunks; uint total_pixels; uint write_depth; uint plane_forms;
} p;

const float ALPHA_MAX = 0.99, T_MIN = 1e-4;
shared vec4 s_w0[256], s_w1[256], s_w2[256], s_col[256];
shared float s_cut[256];
#ifdef RASTER_CONIC
// Per pair, its footprint as a conic in this view's image plane, centred on the splat (footprint_conic): a pixel
// tests it (two loads, a few multiply-adds) before the ray test, which most pairs fail in most of a tile when the
// tile holds many pairs for its pixels (small faces). Large faces use the kernel without it (renderer.py
// CONIC_MAX_FACE says why).
shared vec4 s_qa[256], s_qb[256];

// The rays d = fwd + s right + t down that the ray test accepts, m(d) = |o' x Wd|^2 / |Wd|^2 <= c, are those with
// Q(d) = |o' x Wd|^2 - c |Wd|^2 <= 0. Expanded about the splat's centre, d0 = mu / z (z = fwd . mu, s0 and t0 its
// image coordinates), with ds = s - s0, dt = t - t0, a = W right, b = W down, u = ds a.o' + dt b.o' and
// V = |ds a + dt b|^2, it is exactly Q = |o' x (ds a + dt b)|^2 - c V + 2 c u / z - c |o'|^2 / z^2: every term of the
// footprint's own size, so float keeps it where the unexpanded quadric (gs_emit's) cancels for tiny far splats.
// c is inflated as gs_emit inflates it, so rounding never rejects a pixel the ray test would light. Gives
// (s0, t0, A, B) and (2C, 2D, 2E, F) of Q = A ds^2 + 2C ds dt + B dt^2 + 2D ds + 2E dt + F; a splat not well in
// front of the view gets Q = -1 everywhere (the ray test alone decides).
void footprint_conic(vec3 fwd, vec3 r, vec3 dn, vec4 w0, vec4 w1, vec4 w2, float cut, out vec4 qa, out vec4 qb) {
    vec3 ol = vec3(w0.w, w1.w, w2.w);
    // W's rows are R's columns over the dilated scales, so mu = -W^-1 o' = -sum_k w_k o'_k / |w_k|^2
    vec3 mu = -(w0.xyz * (ol.x / dot(w0.xyz, w0.xyz)) + w1.xyz * (ol.y / dot(w1.xyz, w1.xyz))
                + w2.xyz * (ol.z / dot(w2.xyz, w2.xyz)));
    float z = dot(fwd, mu);
    qa = vec4(0.0);
    qb = vec4(0.0, 0.0, 0.0, -1.0);
    if (!(z > 0.2 * length(mu))) return;
    float c = cut * 1.02 + 1e-3;
    vec3 a = vec3(dot(w0.xyz, r), dot(w1.xyz, r), dot(w2.xyz, r));
    vec3 b = vec3(dot(w0.xyz, dn), dot(w1.xyz, dn), dot(w2.xyz, dn));
    // |o'|^2 V - u^2 = |o' x (ds a + dt b)|^2 (Lagrange): taken as cross products, since for a thin splat o', a
    // and b are all dominated by the thin axis and |o'|^2 |a|^2 - (a.o')^2 would cancel to nothing in float
    vec3 xa = cross(ol, a), xb = cross(ol, b);
    float oo = dot(ol, ol), iz = 1.0 / z;
    qa = vec4(dot(r, mu) * iz, dot(dn, mu) * iz, dot(xa, xa) - c * dot(a, a), dot(xb, xb) - c * dot(b, b));
    qb = vec4(2.0 * (dot(xa, xb) - c * dot(a, b)), 2.0 * c * dot(a, ol) * iz, 2.0 * c * dot(b, ol) * iz, -c * oo * iz * iz);
}
#endif
shared uint s_done;
#ifdef RASTER_CUT
// Where a pixel's BEHIND no longer shows (T bT < T_MIN), only FRONT contributions are left to take, and a batch's
// pairs are in the order of their sort depth (gs_preprocess sort_depth): once a pair's sort depth, less the
// farthest any footprint of the batch reaches, is past the pixel's cut, no later pair of the batch can reach FRONT
// and the pixel skips the rest of the batch (a bound with a margin far past rounding: the images are the same bit
// for bit as without it). Per pair its sort depth less its margin, per batch the reach plus the margins (float
// bits: positive floats order as uints). Probes (several views) sort by distance from the origin, compared with the
// cut as a distance along the ray; a batch of one view (all depth cuts are camera frames) by z = forward . mu,
// compared with the cut itself.
shared float s_dist[256];
shared uint s_reach;
// A contribution's closest approach p = along d lies in the footprint, |W (p - mu)|^2 = m <= cut, so
// |p - mu| <= sqrt(cut) s'_max = r (W's rows are R's columns over the dilated scales s'), and |p| >= |mu| - r.
// One view: d's forward part is 1, so along = forward . p >= forward . mu - r. A later pair j has sort depth
// z_j >= z_k (up to the key's dropped bits, 3e-5 relative, and rounding of z_j, ulps of |mu_j|): the margins
// 1e-3 |mu| on pair k's z and on every pair's reach (1e-3 |mu_j| of the batch's max) cover both.
vec2 dist_reach(vec4 w0, vec4 w1, vec4 w2, float cut, bool one_view, vec3 fwd) {
    vec3 ol = vec3(w0.w, w1.w, w2.w);
    vec3 i2 = 1.0 / vec3(dot(w0.xyz, w0.xyz), dot(w1.xyz, w1.xyz), dot(w2.xyz, w2.xyz));  // s'^2
    vec3 mu = -(w0.xyz * (ol.x * i2.x) + w1.xyz * (ol.y * i2.y) + w2.xyz * (ol.z * i2.z));
    float r = sqrt(max(cut, 0.0) * max(i2.x, max(i2.y, i2.z))), l = length(mu);
    if (one_view) return vec2(dot(fwd, mu) - 1e-3 * l, r + 1e-3 * l);
    return vec2(l * (1.0 - 1e-3), r);
}
#endif
#ifdef RASTER_STRIPS
// Per strip of two pixel rows (a warp of 32 lanes on NVIDIA, eight lanes' rows on lavapipe) and per 32 pairs of the
// batch, which pairs' footprints may reach the strip's rows (strip_mask): each strip composites only those, in
// order, and steps over the rest unread. Sub-pixel splats reach one or two strips of eight, so a pixel visits a
// quarter or less of the pairs the tile holds.
shared uint s_bits[64];
shared vec2 s_trow;  // t of the tile's first pixel row, and t from one row to the next
#endif
// The tile's view (forward, right, down) for the loaders, from shared memory: read again each batch rather than
// held in registers through the pixel loop, which would cost occupancy (docs/benchmarks.md: registers).
shared vec3 s_view[3];

#ifdef RASTER_CONIC
// Whether the pixel at image coordinates (s, t) may lie in pair k's footprint (a NaN says it may).
bool conic_hit(uint k, float s, float t) {
    vec4 qa = s_qa[k], qb = s_qb[k];
    float ds = s - qa.x, dt = t - qa.y;
    return !(ds * (qa.z * ds + qb.x * dt + qb.y) + dt * (qa.w * dt + qb.z) + qb.w > 0.0);
}
#endif

#ifndef RASTER_CONIC
// A pair's m along every ray of the view, as exact quadratic forms in the image plane (render/splat_math.py
// plane_form mirrors this, with the derivation). About the centre's ray d0 = mu / z (z = fwd . mu, image coordinates
// s0, t0), d = d0 + ds right + dt down gives Wd = -o'/z + ds a + dt b (a = W right, b = W down), so with
// D0 = |o'|^2 / z^2: m = |o' x Wd|^2 / |Wd|^2 = q / (1 - l + v), q = |ds (o' x a) + dt (o' x b)|^2 / D0,
// l = 2 (ds a.o' + dt b.o') / (z D0), v = |ds a + dt b|^2 / D0; the closest approach is ahead where l < 2, at
// z (1 - l/2) / (1 - l + v) along d. Every term is of the footprint's own size, so float keeps what the ray test's
// cross product of two near-parallel long vectors loses for small far splats, and a pixel evaluates two quadratics
// and a linear form (three shared loads, ~15 operations) where the ray test takes a matrix product, a cross
// product and two dots. Writes (s0, t0, q_ss, q_tt), (2 q_st, l_s, l_t, z), (v_ss, 2 v_st, v_tt, 0) over the
// pair's w0, w1, w2 and negates its cut when the form holds: a splat well in front of the view (z > 0.2 |mu|) whose
// footprint is not so long and thin (q's eigenvalues more than ~1e3 apart) that q would cancel in float. The centre's
// ray (s0, t0) is the one quantity a pixel subtracts from: it comes from the direction preprocess keeps (centre,
// octahedral), as precise as o' itself; mu rebuilt from W and o' is off by ~1e-7 |mu|, which for a splat a thousand
// of its sizes away moved its footprint by 1e-4 of it and flipped edge pixels (tests/test_raster_plane.py's wall).
void plane_form(vec3 fwd, vec3 r, vec3 dn, uint k, vec3 centre) {
    vec4 w0 = s_w0[k], w1 = s_w1[k], w2 = s_w2[k];
    vec3 ol = vec3(w0.w, w1.w, w2.w);
    float zc = dot(fwd, centre);
    if (!(zc > 0.2 * length(centre))) return;
    // the centre's distance for the forms' scale (no cancellation there): W's rows are R's columns over the dilated
    // scales, so mu = -W^-1 o' = -sum_k w_k o'_k / |w_k|^2
    vec3 mu = -(w0.xyz * (ol.x / dot(w0.xyz, w0.xyz)) + w1.xyz * (ol.y / dot(w1.xyz, w1.xyz))
                + w2.xyz * (ol.z / dot(w2.xyz, w2.xyz)));
    float z = zc * (length(mu) / length(centre));
    vec3 a = vec3(dot(w0.xyz, r), dot(w1.xyz, r), dot(w2.xyz, r));
    vec3 b = vec3(dot(w0.xyz, dn), dot(w1.xyz, dn), dot(w2.xyz, dn));
    vec3 xa = cross(ol, a), xb = cross(ol, b);  // cross products: o', a and b are near parallel for thin splats
    float iz = 1.0 / z, id0 = z * z / dot(ol, ol);
    float qss = dot(xa, xa) * id0, qtt = dot(xb, xb) * id0;
    vec3 xab = cross(xa, xb);
    if (!((qss + qtt) * (qss + qtt) <= 1e3 * dot(xab, xab) * id0 * id0)) return;  // 4 det q / tr^2, Lagrange's way
    s_w0[k] = vec4(dot(r, centre) / zc, dot(dn, centre) / zc, qss, qtt);
    s_w1[k] = vec4(2.0 * dot(xa, xb) * id0, 2.0 * dot(a, ol) * iz * id0, 2.0 * dot(b, ol) * iz * id0, z);
    s_w2[k] = vec4(dot(a, a) * id0, 2.0 * dot(a, b) * id0, dot(b, b) * id0, 0.0);
    s_cut[k] = -s_cut[k];
}
#endif

#ifdef RASTER_STRIPS
// The tile's strips of two rows that a footprint e(ds, dt) = A ds^2 + B2 ds dt + C dt^2 + D ds + E dt + F <= 0 about
// the image point (., t0) may reach, as bits (render/splat_math.py strip_mask mirrors it): the rows t where
// min over s of e <= 0, an interval where e's quadratic part is positive definite, widened by far more than e's
// rounding at a pixel; every strip when e is not an ellipse (the ray test alone decides those pairs) or too thin to
// bound in float, none when no row's pixel centre is within reach. Assumes TILE = 16: eight strips of two rows.
uint strip_mask(float t0, float A, float B2, float C, float D, float E, float F) {
    float ia = 0.25 / A;
    float a = C - B2 * B2 * ia, b = E - B2 * D * (2.0 * ia), cc = F - D * D * ia;
    // a needle's a cancels in float (its error grows as the form's condition, tr^2 / det = (A + C)^2 / (A a)):
    // past STRIP_MAX_COND it takes every strip
    if (!(A > 0.0 && a > 0.0 && (A + C) * (A + C) <= STRIP_MAX_COND * (A * a))) return 0xFFu;
    float h = sqrt(max(b * b - 4.0 * a * cc, 0.0)) / (2.0 * a), mid = -b / (2.0 * a);
    vec2 tr = s_trow;
    float pad = STRIP_PAD_REL * (h + abs(mid) + tr.y) + STRIP_PAD_ABS * (abs(t0) + 1.0);
    float lo = ceil((t0 + mid - h - pad - tr.x) / tr.y), hi = floor((t0 + mid + h + pad - tr.x) / tr.y);
    if (isnan(lo) || isnan(hi)) return 0xFFu;
    if (hi < 0.0 || lo > 15.0 || lo > hi) return 0u;
    uint s0 = uint(max(lo, 0.0)) / 2u, s1 = uint(min(hi, 15.0)) / 2u;
    return ((2u << s1) - 1u) & ~((1u << s0) - 1u);
}

#ifndef RASTER_CONIC
// Pair k's strips from its plane form: the footprint test m <= c is e = q - c (1 - l + v) <= 0
uint plane_strips(uint k) {
    float cut = s_cut[k];
    if (!(cut < 0.0)) return 0xFFu;
    vec4 f0 = s_w0[k], f1 = s_w1[k], f2 = s_w2[k];
    float c = -cut;
    return strip_mask(f0.y, f0.z - c * f2.x, f1.x - c * f2.y, f0.w - c * f2.z, c * f1.y, c * f1.z, -c);
}
#endif

#endif

// Pair k of the batch along the pixel's ray d (image coordinates s, t): composited front to back if the ray passes
// within its footprint. Returns whether the pixel is now opaque. Unlike 3DGS, the splat that crosses T_MIN is kept:
// the rule then composes chunk by chunk, and a nearly opaque last splat does not leave up to 1% of transmittance
// behind. A negative s_cut says the pair holds its plane form (plane_form): the same for every pixel of the tile,
// so the branch does not diverge.
bool composite(uint k, vec3 d, float s, float t, inout vec3 color, inout float T, inout float zsum CUT_PARAMS) {
#ifdef RASTER_CUT
    // cut_far: the cut in the batch's sort depth plus the batch's reach (per batch; dist_reach)
    if (T * bT < T_MIN && s_dist[k] >= cut_far) { skip = true; return false; }
#endif
    float cut = s_cut[k], m, along;
#ifndef RASTER_CONIC
    if (cut < 0.0) {
        vec4 f0 = s_w0[k], f1 = s_w1[k], f2 = s_w2[k];
        float ds = s - f0.x, dt = t - f0.y;
        float q = ds * (f0.z * ds + f1.x * dt) + f0.w * (dt * dt);
        float l = f1.y * ds + f1.z * dt;
        float den = 1.0 - l + (ds * (f2.x * ds + f2.y * dt) + f2.z * (dt * dt));  // |Wd|^2 / D0 > 0
        if (q > -cut * den || l >= 2.0) return false;  // outside the footprint, or the approach behind the origin
        float iden = 1.0 / den;
        m = q * iden;
        along = f1.w * (1.0 - 0.5 * l) * iden;
    } else
#endif
    {
        vec3 ol = vec3(s_w0[k].w, s_w1[k].w, s_w2[k].w);
        vec3 dl = vec3(dot(s_w0[k].xyz, d), dot(s_w1[k].xyz, d), dot(s_w2[k].xyz, d));
        float od = dot(ol, dl);
        if (od >= 0.0) return false;  // the closest approach lies behind the origin
        vec3 cr = cross(ol, dl);
        float cc = dot(cr, cr), dd = dot(dl, dl);
        if (cc > cut * dd) return false;  // outside the footprint (3DGS: alpha < 1/255); m = cc / dd
        m = cc / dd;
        along = -od / dd;  // closest approach along d; d's forward part is 1
    }
    float alpha = min(ALPHA_MAX, s_col[k].w * exp(-0.5 * m));
#ifdef RASTER_CUT
    if (along >= cut_z) {  // at or beyond the mesh: BEHIND, until it is opaque behind what FRONT lets through
        if (T * bT >= T_MIN) {
            bcolor += bT * alpha * s_col[k].rgb;
            if (p.write_depth != 0u) bzsum += bT * alpha * along;
            bT *= 1.0 - alpha;
        }
        return false;
    }
#endif
    color += T * alpha * s_col[k].rgb;
    if (p.write_depth != 0u) zsum += T * alpha * along;
    T *= 1.0 - alpha;
    return T < T_MIN;
}

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
    float s = view_s(vw, px), t = view_t(vw, py);
    vec3 d = vw.fwd.xyz + s * vw.right_tanx.xyz + t * vw.down_tany.xyz;
    // where this pixel's result goes, so that nothing of the view stays live through the loop
    uint pixel_index = probe * probe_pixels + vw.extra.x + py * vw.dims.x + px;
    uint out_index = pixel_index + (p.chunks > 1u ? chunk * p.total_pixels : 0u);
#ifdef RASTER_CUT
    float cut_z = inside ? cuts[pixel_index] : 0.0;
    // the cut in the batch's sort depth: along the view axis (one view) or as a distance along the ray (dist_reach)
    float cut_dist = p.n_views == 1u ? cut_z : cut_z * length(d), cut_far;
    vec3 bcolor = vec3(0.0);
    float bT = 1.0, bzsum = 0.0;
    bool skip;
#endif
    if (gl_LocalInvocationIndex == 0u) {
        s_view[0] = vw.fwd.xyz; s_view[1] = vw.right_tanx.xyz; s_view[2] = vw.down_tany.xyz;
#ifdef RASTER_STRIPS
        s_trow = vec2(t, 2.0 * vw.down_tany.w / vw.grid.w);  // lane 0's row is the tile's first
#endif
    }

    uvec2 whole = ranges[probe * p.total_tiles + g];
    uint len = whole.y - whole.x;
    uint q = len / p.chunks, rem = len % p.chunks;  // chunk c starts at c*q + min(c, rem): no overflow
    uvec2 range = whole.x + uvec2(chunk * q + min(chunk, rem), (chunk + 1u) * q + min(chunk + 1u, rem));
    uint lid = gl_LocalInvocationIndex;
    bool done = !inside;
    vec3 color = vec3(0.0);
    float T = 1.0, zsum = 0.0;
    uint start = range.x;
    for (; start < range.y; start += 256u) {
        barrier();
        if (lid == 0u) s_done = 0u;
#ifdef RASTER_CUT
        if (lid == 0u) s_reach = 0u;
#endif
#ifdef RASTER_STRIPS
        if (lid < 64u) s_bits[lid] = 0u;
#endif
        barrier();
        if (done) atomicAdd(s_done, 1u);
        uint j = start + lid;
        if (j < range.y) {
            uint i = inst_val[j];
            s_w0[lid] = prepared[PREP * i]; s_w1[lid] = prepared[PREP * i + 1u];
            s_w2[lid] = prepared[PREP * i + 2u]; s_col[lid] = prepared[PREP * i + 3u];
            vec4 e = prepared[PREP * i + 4u];
            s_cut[lid] = e.x;
#ifdef RASTER_CUT
            vec2 dr = dist_reach(s_w0[lid], s_w1[lid], s_w2[lid], e.x, p.n_views == 1u, s_view[0]);
            s_dist[lid] = dr.x;
            atomicMax(s_reach, floatBitsToUint(dr.y));
#endif
#ifdef RASTER_CONIC
            footprint_conic(s_view[0], s_view[1], s_view[2], s_w0[lid], s_w1[lid], s_w2[lid], s_cut[lid], s_qa[lid],
                            s_qb[lid]);
#ifdef RASTER_STRIPS
            vec4 qa = s_qa[lid], qb = s_qb[lid];
            uint strips = strip_mask(qa.y, qa.z, qb.x, qa.w, qb.y, qb.z, qb.w);
#endif
#else
            if (p.plane_forms != 0u) plane_form(s_view[0], s_view[1], s_view[2], lid, from_octahedral(e.zw));
#ifdef RASTER_STRIPS
            uint strips = plane_strips(lid);
#endif
#endif
#ifdef RASTER_STRIPS
            [[unroll]] for (uint w = 0u; w < 8u; ++w)  // unrolled: lavapipe counts every loop step (LOOP_PAIRS)
                if ((strips & (1u << w)) != 0u) atomicOr(s_bits[w * 8u + lid / 32u], 1u << (lid % 32u));
#endif
        }
        barrier();
        if (s_done == 256u) break;
#ifdef RASTER_CUT
        skip = false;
        cut_far = cut_dist + uintBitsToFloat(s_reach) * (1.0 + 1e-3);
#endif
        uint batch = min(256u, range.y - start);
#ifdef RASTER_STRIPS
        // the strip's pairs, lowest first (front to back); with the conic, each one's conic before its ray test
        uint strip = gl_LocalInvocationID.y / 2u;
        for (uint w = 0u; w < 8u && !done AND_NOT_SKIPPED; ++w) {
            uint bits = s_bits[strip * 8u + w];
            while (bits != 0u && !done AND_NOT_SKIPPED) {
                uint k = w * 32u + uint(findLSB(bits));
                bits &= bits - 1u;
#ifdef RASTER_CONIC
                if (conic_hit(k, s, t))
#endif
                done = composite(k, d, s, t, color, T, zsum CUT_ARGS);
            }
        }
#elif defined(RASTER_CONIC)
        // 32 pairs' conics first, then the ray test of those that pass, lowest first (front to back). The mask
        // loop runs its 32 steps whatever the batch holds, the bound tested inside: bounded by the batch's
        // remainder, lavapipe rastered one tile of the guitar test wrongly.
        for (uint k0 = 0u; k0 < batch && !done AND_NOT_SKIPPED; k0 += 32u) {
            uint mask = 0u;
            for (uint bit = 0u; bit < 32u; ++bit)
                if (k0 + bit < batch && conic_hit(k0 + bit, s, t)) mask |= 1u << bit;
            while (mask != 0u && !done AND_NOT_SKIPPED) {
                uint bit = uint(findLSB(mask));
                mask &= mask - 1u;
                done = composite(k0 + bit, d, s, t, color, T, zsum CUT_ARGS);
            }
        }
#else
        // not unrolled: the pixel loop's registers are what bounds this kernel (docs/benchmarks.md: registers), and
        // the 53-register build measured best on an H200 had it so
        [[dont_unroll]] for (uint k = 0u; k < batch && !done AND_NOT_SKIPPED; ++k)
            done = composite(k, d, s, t, color, T, zsum CUT_ARGS);
#endif
    }
    // the pairs this workgroup went through: up to the batch where every pixel was opaque, or the whole chunk
    if (lid == 0u) atomicMax(count[3], min(start, range.y) - range.x);
#ifdef RASTER_CUT
    // the depth of FRONT over BEHIND (the splats without the mesh): sum(T alpha z) of both over their coverage
    if (inside) {
        if (p.chunks == 1u) {
            image[out_index] = vec4(color, 1.0 - T);
            behind[out_index] = vec4(bcolor, 1.0 - bT);
            float tt = T * bT;
            if (p.write_depth != 0u) depth[out_index] = tt < 1.0 ? (zsum + T * bzsum) / (1.0 - tt) : 0.0;
        } else {
            image[out_index] = vec4(color, T);
            behind[out_index] = vec4(bcolor, bT);
            if (p.write_depth != 0u) { depth[2u * out_index] = zsum; depth[2u * out_index + 1u] = bzsum; }
        }
    }
#else
    if (inside) {
        if (p.chunks == 1u) {
            image[out_index] = vec4(color, 1.0 - T);
            if (p.write_depth != 0u) depth[out_index] = T < 1.0 ? zsum / (1.0 - T) : 0.0;
        } else {
            image[out_index] = vec4(color, T);
            if (p.write_depth != 0u) depth[out_index] = zsum;
        }
    }
#endif
}
