#version 450
// One RGBA cube face resampled to another size (probe/box.py::faces_to_size): to a smaller face, each target texel
// the solid-angle-weighted mean of the n/m x n/m texels it covers (one step: what halving repeatedly gives); to a
// larger one, bilinear doubling within the face (tolerance.upsample2, edges clamped) repeated log2(m/n) times,
// its weights on the source texels carried through the doublings here so one pass gives the same sum.
// Face sizes are powers of two. One thread per target texel; src_at / dst_at: the faces' first texels.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Src { vec4 src[]; };
layout(std430, binding = 1) readonly buffer Omega { float omega[]; };  // the source face's n*n solid angles
layout(std430, binding = 2) writeonly buffer Dst { vec4 dst[]; };
layout(push_constant) uniform P { uint n; uint m; uint src_at; uint dst_at; } p;

// Weights of the source texels lo .. lo+5 that k doublings of a row of n texels give target texel t.
void doubled(uint t, uint k, out int lo, out float w[6]) {
    for (int e = 0; e < 6; ++e) w[e] = 0.0;
    w[0] = 1.0;
    lo = int(t);
    for (uint level = k; level > 0u; --level) {
        int half_n = int(p.n << (level - 1u));  // the row's size one doubling down
        int lo2 = (lo >> 1) - 1;
        float nw[6];
        for (int e = 0; e < 6; ++e) nw[e] = 0.0;
        for (int e = 0; e < 6; ++e) {
            if (w[e] == 0.0) continue;
            int c = lo + e, i = c >> 1;
            int nb = (c & 1) == 1 ? min(i + 1, half_n - 1) : max(i - 1, 0);
            nw[i - lo2] += 0.75 * w[e];
            nw[nb - lo2] += 0.25 * w[e];
        }
        lo = lo2;
        w = nw;
    }
}

void main() {
    uint idx = linear_group() * 64u + gl_LocalInvocationID.x;
    if (idx >= p.m * p.m) return;
    uint J = idx / p.m, I = idx % p.m;
    vec4 v = vec4(0.0);
    if (p.n >= p.m) {
        uint f = p.n / p.m;
        float wsum = 0.0;
        for (uint dj = 0u; dj < f; ++dj)
            for (uint di = 0u; di < f; ++di) {
                uint j = J * f + dj, i = I * f + di;
                float w = omega[j * p.n + i];
                v += w * src[p.src_at + j * p.n + i];
                wsum += w;
            }
        v /= wsum;
    } else {
        uint k = uint(findMSB(p.m / p.n));
        int ly, lx;
        float wy[6], wx[6];
        doubled(J, k, ly, wy);
        doubled(I, k, lx, wx);
        for (int a = 0; a < 6; ++a) {
            if (wy[a] == 0.0) continue;
            for (int b = 0; b < 6; ++b)
                if (wx[b] != 0.0) v += wy[a] * wx[b] * src[p.src_at + uint(ly + a) * p.n + uint(lx + b)];
        }
    }
    dst[p.dst_at + idx] = v;
}
