#version 450
// The light volume's maps from a render_probes frame with depth, step 1 of 2 (probe/gpu_volume_maps.py; the numpy
// reference is probe/volume_bake.py maps_from_cubes): per probe and texel of the irradiance's cube (g^2 faces, the
// frame's f^2 box-averaged by k = f/g), RGB with the holes filled by the hole colour, and w = sum of the block's
// hole x dOmega; per texel of the frame (visibility keeps f^2), (r, r^2, dOmega where a covered texel is nearer
// than `near`, 0), r the radial distance (depth z x |(s, t, 1)|) or `far` where coverage < `covered`.
// One thread per irradiance texel; the frame's probes one after another.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Frame { vec4 frame[]; };
layout(std430, binding = 1) readonly buffer Depth { float depth[]; };
layout(std430, binding = 2) readonly buffer Omega { float omega[]; };  // f*f solid angles (every face's)
layout(std430, binding = 3) writeonly buffer IrrIn { vec4 irr_in[]; };
layout(std430, binding = 4) writeonly buffer VisIn { vec4 vis_in[]; };
layout(push_constant) uniform P {
    uint n; uint f; uint g; float far; float near; float covered; float hole_r; float hole_g; float hole_b;
} p;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= p.n) return;
    uint gg = p.g * p.g, k = p.f / p.g;
    uint probe_face = idx / gg, rem = idx % gg, J = rem / p.g, I = rem % p.g;
    vec3 hole_rgb = vec3(p.hole_r, p.hole_g, p.hole_b);
    vec3 sum = vec3(0.0);
    float holes = 0.0;
    for (uint dj = 0u; dj < k; ++dj)
        for (uint di = 0u; di < k; ++di) {
            uint j = J * k + dj, i = I * k + di;
            uint t = (probe_face * p.f + j) * p.f + i;
            vec4 c = frame[t];
            float h = clamp(1.0 - c.a, 0.0, 1.0);
            float sa = omega[j * p.f + i];
            sum += c.rgb + h * hole_rgb;
            holes += h * sa;
            float s = (float(i) + 0.5) / float(p.f) * 2.0 - 1.0, tt = (float(j) + 0.5) / float(p.f) * 2.0 - 1.0;
            bool seen = c.a >= p.covered;
            float r = seen ? depth[t] * sqrt(1.0 + s * s + tt * tt) : p.far;
            vis_in[t] = vec4(r, r * r, (seen && r < p.near) ? sa : 0.0, 0.0);
        }
    irr_in[idx] = vec4(sum / float(k * k), holes);
}
