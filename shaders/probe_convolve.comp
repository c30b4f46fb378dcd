#version 450
// Cosine-weighted hemisphere convolution (probe/convolve.py): per output texel normal n, a midpoint grid of
// phi_steps x theta_steps directions in n's tangent frame, weights cos(theta) sin(theta) normalised by their
// sum, radiance read by seamless bilinear lookup. Out: E/pi. One thread per output texel.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(std430, binding = 0) readonly buffer Cube { float cube[]; };
#define PROBE_CUBE_BUFFER cube
#define PROBE_CUBE_OFFSET 0u
#include "probe_cube.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 1) writeonly buffer Out { float outp[]; };
layout(push_constant) uniform P { uint n; uint m; uint phi_steps; uint theta_steps; } p;
const float PI = 3.14159265358979;

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= 6u * p.m * p.m) return;
    uint face = idx / (p.m * p.m), rem = idx % (p.m * p.m);
    vec3 nrm = texel_dir(face, rem % p.m, rem / p.m, p.m);
    // Tangent frame as probe/reference.py::tangent_frames (helper Z, or X within ~2.6 degrees of the poles).
    vec3 helper = abs(nrm.z) < 0.999 ? vec3(0, 0, 1) : vec3(1, 0, 0);
    vec3 tng = normalize(cross(helper, nrm));
    vec3 btg = cross(nrm, tng);
    float dphi = 2.0 * PI / float(p.phi_steps), dtheta = 0.5 * PI / float(p.theta_steps);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (uint a = 0u; a < p.theta_steps; ++a) {
        float th = (float(a) + 0.5) * dtheta;
        float st = sin(th), ct = cos(th);
        float w = ct * st;
        vec3 ring = vec3(0.0);
        for (uint b = 0u; b < p.phi_steps; ++b) {
            float ph = (float(b) + 0.5) * dphi;
            vec3 d = st * cos(ph) * tng + st * sin(ph) * btg + ct * nrm;
            ring += cube_bilinear(d, p.n);
        }
        sum += w * ring;
        wsum += w * float(p.phi_steps);
    }
    vec3 e = sum / wsum;
    outp[idx * 3u] = e.r; outp[idx * 3u + 1u] = e.g; outp[idx * 3u + 2u] = e.b;
}
