#version 450
// GGX prefiltered radiance (probe/ggx.py::ggx_prefilter_level), every roughness level in one dispatch.
// Per output normal n: prefiltered(n) = sum_s w_s L(mip lod_s, frame(n) * l_s), with the host's sample table
// (ggx.ggx_samples: Hammersley half-vectors reflected about n = v, N.L weights already divided by their sum,
// lod from the pdf) so GPU and numpy use the very same samples. Roughness 0 is one sample (0, 0, 1), weight 1,
// at the output's mip. L is read trilinearly from the solid-angle mip chain (box.mip_chain), packed level
// after level in one buffer. One workgroup per output texel: its 64 threads stride over the samples, then a
// shared-memory tree adds their partial sums.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(std430, binding = 0) readonly buffer Mips { float mips[]; };        // levels n, n/2, ... packed RGB
uint mip_base;  // float index of the level cube_bilinear reads (set before each read)
#define PROBE_CUBE_BUFFER mips
#define PROBE_CUBE_OFFSET mip_base
#include "probe_cube.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 1) readonly buffer Samples { vec4 samp[]; };     // (local light dir, weight)
layout(std430, binding = 2) readonly buffer Lods { float lod[]; };        // per sample, unclamped
layout(std430, binding = 3) readonly buffer Levels { uvec4 level[]; };    // (size, first texel, first sample, count)
layout(std430, binding = 4) writeonly buffer Out { float outp[]; };      // every level's cube, packed RGB
layout(push_constant) uniform P { uint n; uint n_mips; uint n_levels; uint total; } p;
shared vec3 red[64];

// Trilinear read as probe/sampling.py::sample_mips_trilinear: bilinear per level, linear between two levels.
vec3 mip_read(vec3 d, float lv) {
    lv = clamp(lv, 0.0, float(p.n_mips - 1u));
    uint lo = uint(floor(lv));
    float frac = lv - float(lo);
    uint base = 0u, size = p.n;
    for (uint k = 0u; k < lo; ++k) { base += 18u * size * size; size >>= 1; }
    vec3 acc = vec3(0.0);
    uint reads = frac > 0.0 ? 2u : 1u;  // a loop, not two inlined reads: lavapipe compiles on first use
    for (uint e = 0u; e < reads; ++e) {
        mip_base = base;
        acc += (e == 0u ? 1.0 - frac : frac) * cube_bilinear(d, size);
        base += 18u * size * size;
        size >>= 1;
    }
    return acc;
}

void main() {
    uint o = linear_group();
    if (o >= p.total) return;  // uniform per workgroup, so no thread misses the barriers below
    uvec4 lvl = level[0];
    for (uint k = 1u; k < p.n_levels; ++k)
        if (o >= level[k].y) lvl = level[k];
    uint m = lvl.x, t = o - lvl.y;
    uint face = t / (m * m), rem = t % (m * m);
    vec3 nrm = texel_dir(face, rem % m, rem / m, m);
    // Tangent frame as probe/reference.py::tangent_frames (helper Z, or X within ~2.6 degrees of the poles).
    vec3 helper = abs(nrm.z) < 0.999 ? vec3(0, 0, 1) : vec3(1, 0, 0);
    vec3 tng = normalize(cross(helper, nrm));
    vec3 btg = cross(nrm, tng);
    uint lid = gl_LocalInvocationID.x;
    vec3 acc = vec3(0.0);
    for (uint s = lid; s < lvl.w; s += 64u) {
        vec4 l = samp[lvl.z + s];
        acc += l.w * mip_read(l.x * tng + l.y * btg + l.z * nrm, lod[lvl.z + s]);
    }
    red[lid] = acc;
    barrier();
    for (uint stride = 32u; stride > 0u; stride >>= 1) {
        if (lid < stride) red[lid] += red[lid + stride];
        barrier();
    }
    if (lid == 0u) {
        vec3 v = red[0];
        outp[o * 3u] = v.r; outp[o * 3u + 1u] = v.g; outp[o * 3u + 2u] = v.b;
    }
}
