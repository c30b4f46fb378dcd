#version 450
// Per splat, once for all views of the batch: cull, whitening transform for the per-ray evaluation, SH colour
// toward the origin, the number of tiles it touches over all views, and its depth key (distance from the origin).
// With a level of detail (p.lod = 1; render/lod.py) the splats are the nodes of its tree and each first decides
// whether it is in the probe's cut. With p.compact = 1 (a level of detail, or a single view, which sees a fraction
// of the splats) the drawn ones are flagged in `live` for gs_lod_compact, and only they are depth-sorted.
// Several probes in one batch (SplatRenderer.render_probes): workgroup x is the probe and (y, z) the block of 256
// splats, and every output is per (probe, splat) pair at index probe * n + splat, so the later stages, which only
// ever see pair indices, need no change; a pair's first tile in the batch travels in prepared[.. + 4].y for
// gs_emit. x varies fastest in dispatch order, so the probes of one block run side by side and a splat's data
// (SH: 192 bytes at degree 3) is read from memory about once per group of probes, not once per probe.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer PosOp { vec4 pos_op[]; };
layout(std430, binding = 1) readonly buffer Scale { vec4 scale[]; };
layout(std430, binding = 2) readonly buffer Rot { vec4 rot[]; };
layout(std430, binding = 3) readonly buffer SH { float sh[]; };
layout(std430, binding = 4) readonly buffer Views { View views[]; };
layout(std430, binding = 5) writeonly buffer Prepared { vec4 prepared[]; };
layout(std430, binding = 6) writeonly buffer TileCount { uint tile_count[]; };
layout(std430, binding = 7) writeonly buffer DepthKey { uint depth_key[]; };
layout(std430, binding = 8) writeonly buffer DepthVal { uint depth_val[]; };
layout(std430, binding = 9) writeonly buffer Rects { uvec2 rects[]; };  // per splat and view, for gs_emit
// The origin travels in a buffer, not a push constant, so a recorded command buffer serves any probe position.
layout(std430, binding = 10) readonly buffer Origin { vec4 origins[]; };  // one per probe (workgroup z)
// Per node: x = cell x | cell y << 16, y = cell z | level << 16 | parent level << 24 (LodTree.words()).
layout(std430, binding = 11) readonly buffer Lod { uvec2 lod[]; };
layout(std430, binding = 12) writeonly buffer Live { uint live[]; };
layout(push_constant) uniform P {
    uint n; float dilation_angle; float near; uint sh_k; uint n_views;
    uint energy_preserving;  // 1: the dilation keeps each splat's integral (probes); 0: 3DGS's look (views)
    uint lod;  // 1: nodes of a level of detail, drawn where in the cut of threshold lod_tau
    float lod_tau; float lod_cell; float lod_ox; float lod_oy; float lod_oz;  // threshold, level-1 cell, grid corner
    uint srgb;  // the scene's colour space (core/colour.py): 1 "srgb" (trained on photos), 0 "linear"
    uint sort_order;  // SORT_RADIAL or SORT_VIEW_DEPTH (constants.py): the batch's ViewBatch.sort
    uint sh_splat_major;  // the SH buffer's layout (render/upload.py): 1 splat-major (N, K, 3), 0 (K, 3, N)
    uint compact;  // 1: flag drawn pairs in `live` (packed by gs_lod_compact), leave depth_val and tile_count
} p;

const uint LOD_NO_PARENT = 255u;  // render/lod.py NO_PARENT: no stored ancestor, its error is infinite

// size <= tau * distance(origin, cell box): the cell (level >= 1) is fine enough for this probe.
vec3 origin;  // this invocation's probe

bool fine_enough(uint level, uvec3 c) {
    float size = p.lod_cell * exp2(float(level) - 1.0);
    vec3 lo = vec3(p.lod_ox, p.lod_oy, p.lod_oz) + vec3(c) * size;
    vec3 d = max(max(lo - origin, origin - (lo + size)), vec3(0.0));
    return size <= p.lod_tau * length(d);
}

// The cut (lod.cut): a node is drawn iff it is fine enough and its nearest stored ancestor is not. Errors grow
// up the tree, so every splat is drawn through exactly one node.
bool in_cut(uvec2 w) {
    uint level = (w.y >> 16) & 0xFFu, parent = w.y >> 24;
    uvec3 c = uvec3(w.x & 0xFFFFu, w.x >> 16, w.y & 0xFFFFu);  // at level max(level, 1)
    if (level > 0u && !fine_enough(level, c)) return false;
    if (parent == LOD_NO_PARENT) return true;
    return !fine_enough(parent, c >> (parent - max(level, 1u)));
}

const float C0 = 0.28209479177387814, C1 = 0.4886025119029199;

// Coefficient-major SH (sh[(k * 3 + channel) * n + splat]) gives a warp contiguous loads when all its lanes draw; a
// splat-major one (sh[(splat * K + k) * 3 + channel]) reads one splat's 48 words from one or two cache lines, which
// is what a camera view's preprocess wants, where about one lane in eight is in view (renderer.SH_SPLAT_MAJOR).
vec3 sh_coeff(uint i, uint k) {
    if (p.sh_splat_major != 0u) {
        uint b = (i * p.sh_k + k) * 3u;
        return vec3(sh[b], sh[b + 1u], sh[b + 2u]);
    }
    uint b = 3u * k * p.n + i;
    return vec3(sh[b], sh[b + p.n], sh[b + 2u * p.n]);
}

// The colour rule, the one place the GPU applies it (numpy mirror: core/colour.py splat_radiance). "srgb": the
// sRGB decoding curve extended as Blender's Cycles does (negatives 0, ((c + 0.055) / 1.055)^2.4 above 0.04045,
// unclamped above 1); "linear": c is radiance already. Either way negatives give no light.
vec3 splat_radiance(vec3 c) {
    if (p.srgb == 0u) return max(c, vec3(0.0));
    vec3 lo = max(c, vec3(0.0)) * (1.0 / 12.92);
    vec3 hi = pow((max(c, vec3(0.04045)) + 0.055) * (1.0 / 1.055), vec3(2.4));
    return mix(hi, lo, lessThan(c, vec3(0.04045)));
}

vec3 sh_color(uint i, vec3 d) {
    vec3 c = C0 * sh_coeff(i, 0u);
    if (p.sh_k > 1u) {
        float x = d.x, y = d.y, z = d.z;
        float basis[16];
        basis[1] = -C1 * y; basis[2] = C1 * z; basis[3] = -C1 * x;
        if (p.sh_k > 4u) {
            float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
            basis[4] = 1.0925484305920792 * xy; basis[5] = -1.0925484305920792 * yz;
            basis[6] = 0.31539156525252005 * (2.0 * zz - xx - yy); basis[7] = -1.0925484305920792 * xz;
            basis[8] = 0.5462742152960396 * (xx - yy);
            if (p.sh_k > 9u) {
                basis[9] = -0.5900435899266435 * y * (3.0 * xx - yy); basis[10] = 2.890611442640554 * xy * z;
                basis[11] = -0.4570457994644658 * y * (4.0 * zz - xx - yy);
                basis[12] = 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
                basis[13] = -0.4570457994644658 * x * (4.0 * zz - xx - yy);
                basis[14] = 1.445305721320277 * z * (xx - yy); basis[15] = -0.5900435899266435 * x * (xx - 3.0 * yy);
            }
        }
        for (uint k = 1u; k < p.sh_k; ++k) c += basis[k] * sh_coeff(i, k);
    }
    return splat_radiance(c + 0.5);
}

// The sort depth's float bits without their low DEPTH_KEY_SHIFT (constants.py). Splats are uploaded in tie order
// (render/splat_math.py tie_order), which the stable sort keeps among equal keys: co-distant splats composite in
// the order of a hash of their position, not of the file's storage.
uint depth_sort_key(float dist) {
    return floatBitsToUint(dist) >> DEPTH_KEY_SHIFT;
}

// The sort depth (splat_math.depth_keys), as the batch says (ViewBatch.sort): SORT_VIEW_DEPTH (a camera view:
// camera frames, the viewport) by depth along its view axis, z = forward . mu, as 3DGS does, clamped to
// SORT_DEPTH_MIN (> 0: positive floats order as their bits) so that a splat centred behind the camera plane comes
// first; SORT_RADIAL (probes, also one face of a probe rendered alone: its faces share one order) by distance from
// the origin. gs_raster.glsl's depth-cut skip relies on this order (dist_reach).
const float SORT_DEPTH_MIN = 1e-20;
float sort_depth(vec3 mu, float dist) {
    return p.sort_order == SORT_VIEW_DEPTH ? max(dot(views[0].fwd.xyz, mu), SORT_DEPTH_MIN) : dist;
}

void main() {
    uint i = (gl_WorkGroupID.z * gl_NumWorkGroups.y + gl_WorkGroupID.y) * 256u + gl_LocalInvocationID.x;  // splat
    if (i >= p.n) return;
    uint probe = gl_WorkGroupID.x;
    uint q = probe * p.n + i;  // the (probe, splat) pair: index of every per-pair output
    origin = origins[probe].xyz;
    depth_key[q] = 0xFFFFFFFFu;
    if (p.compact != 0u) {
        live[q] = 0u;  // the compaction reads depth_val (its pair) and tile_count of drawn pairs only
    } else {
        depth_val[q] = q;
        tile_count[q] = 0u;
    }
    // nodes out of the cut read nothing more: most of a big scene's nodes end here
    if (p.lod != 0u && !in_cut(lod[i])) return;
    vec4 po = pos_op[i];
    vec3 mu = po.xyz - origin;
    float dist = length(mu);
    vec3 sc = scale[i].xyz;
    vec3 s2 = dilated_scale2(sc, dist, p.dilation_angle);
    mat3 R = quat_to_mat(rot[i]);
    float opacity = po.w;
    if (p.energy_preserving != 0u) {
        // The footprint seen along u is the covariance projected on the plane normal to u; the dilation adds
        // delta^2 there. Keep its integral: opacity * sqrt(det / det'), with det = u^T adj(Sigma) u.
        vec3 u = mu / dist;
        vec3 c = vec3(dot(u, R[0]), dot(u, R[1]), dot(u, R[2]));
        c *= c;
        vec3 q = sc * sc;
        float det = c.x * q.y * q.z + c.y * q.x * q.z + c.z * q.x * q.y;
        float tr = dot(q, vec3(1.0) - c);
        float dl = s2.x - q.x;  // delta^2
        opacity *= sqrt(det / max(det + dl * tr + dl * dl, 1e-38));
    }
    // The footprint is 3DGS's (alpha of the undimmed splat >= 1/255), whatever the energy-preserving dimming.
    float cutoff = 2.0 * log(255.0 * po.w);
    if (!(dist > p.near) || !(cutoff > 0.0)) return;
    mat3 cov = cut_covariance(R, s2, cutoff);
    // gs_emit reads every view's rectangle of a drawn pair and none of a culled one: a culled pair writes none (a
    // camera view culls ~7 of 8 splats, and each write would take a sector of its own), a drawn one zeros its misses
    uint count = 0u, missed = 0u;
    for (uint v = 0u; v < p.n_views; ++v) {
        uvec4 rc;
        if (view_rect(views[v], mu, cov, rc)) {
            count += (rc.z - rc.x) * (rc.w - rc.y);
            rects[q * MAX_VIEWS + v] = uvec2(rc.x | (rc.y << 16), rc.z | (rc.w << 16));
        } else {
            missed |= 1u << v;
        }
    }
    if (count == 0u) return;
    for (uint v = 0u; missed != 0u && v < p.n_views; ++v)
        if ((missed & (1u << v)) != 0u) rects[q * MAX_VIEWS + v] = uvec2(0u);
    if (p.compact != 0u) live[q] = 1u;
    vec3 inv = inversesqrt(s2);
    vec3 w0 = R[0] * inv.x, w1 = R[1] * inv.y, w2 = R[2] * inv.z;  // rows of W = diag(1/s') R^T
    vec3 ol = -vec3(dot(w0, mu), dot(w1, mu), dot(w2, mu));
    // tiles of one probe: the last view's first tile + its tiles (views are numbered the same for every probe)
    View last = views[p.n_views - 1u];
    uint probe_tiles = last.dims.w + last.dims.z * last.extra.y;
    prepared[PREP * q + 0u] = vec4(w0, ol.x);
    prepared[PREP * q + 1u] = vec4(w1, ol.y);
    prepared[PREP * q + 2u] = vec4(w2, ol.z);
    prepared[PREP * q + 3u] = vec4(sh_color(i, mu / dist), opacity);
    // .y: exact below 2^24 (renderer.py); .zw: the centre's direction, octahedral, for the raster's plane forms
    prepared[PREP * q + 4u] = vec4(cutoff, float(probe * probe_tiles), octahedral(mu));
    tile_count[q] = count;
    depth_key[q] = depth_sort_key(sort_depth(mu, dist));
}
