#version 450
// Exact irradiance (probe/reference.py::exact_irradiance): for every output normal n,
//   E(n)/pi = sum over every texel w of the radiance cube  L(w) * max(0, n.w) * dOmega(w) / pi.
// The host uploads each texel's unit direction and dOmega/pi (core.cubemap, float64 -> float32), so no cube
// geometry is recomputed here. One workgroup per output texel: its 128 threads stride over the texels, then a
// shared-memory tree adds their partial sums (float32 over <= 6*64^2 terms: ~1e-6 relative).
// Several probes' cubes one after another (a batch, gpu_filters.FilterPlan): workgroup z is the probe.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "probe_cube.glsl"
layout(local_size_x = 128) in;
layout(std430, binding = 0) readonly buffer Cube { float cube[]; };       // 6*N*N packed RGB
layout(std430, binding = 1) readonly buffer Texels { vec4 texel[]; };     // 6*N*N (direction, dOmega / pi)
layout(std430, binding = 2) writeonly buffer Out { float outp[]; };      // 6*M*M packed RGB, E/pi
layout(push_constant) uniform P { uint n; uint m; } p;
shared vec3 red[128];

void main() {
    uint o = linear_group();
    if (o >= 6u * p.m * p.m) return;  // uniform per workgroup, so no thread misses the barriers below
    uint face = o / (p.m * p.m), rem = o % (p.m * p.m);
    vec3 nrm = texel_dir(face, rem % p.m, rem / p.m, p.m);
    uint lid = gl_LocalInvocationID.x;
    uint total = 6u * p.n * p.n, base = gl_WorkGroupID.z * total;
    vec3 acc = vec3(0.0);
    for (uint t = lid; t < total; t += 128u) {
        vec4 w = texel[t];
        float c = dot(nrm, w.xyz);
        if (c > 0.0) acc += (c * w.w) * vec3(cube[(base + t) * 3u], cube[(base + t) * 3u + 1u], cube[(base + t) * 3u + 2u]);
    }
    red[lid] = acc;
    barrier();
    for (uint stride = 64u; stride > 0u; stride >>= 1) {
        if (lid < stride) red[lid] += red[lid + stride];
        barrier();
    }
    if (lid == 0u) {
        vec3 e = red[0];
        uint w = (gl_WorkGroupID.z * 6u * p.m * p.m + o) * 3u;
        outp[w] = e.r; outp[w + 1u] = e.g; outp[w + 2u] = e.b;
    }
}
