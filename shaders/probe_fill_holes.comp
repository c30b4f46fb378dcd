#version 450
// Holes of rendered probes filled on the GPU, as probe/holes.py fill_holes does on the host with a fill constant
// over the sphere ("mean", "constant"): each texel's RGB (premultiplied) gains (1 - clamp(alpha)) times its probe's
// fill; alpha is kept (it still shows coverage). The frame's probes one after another, per_probe texels each.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) buffer Frame { vec4 frame[]; };
layout(std430, binding = 1) readonly buffer Fill { vec4 fill[]; };  // one per probe (rgb; w unused)
layout(push_constant) uniform P { uint n; uint per_probe; } p;

void main() {
    uint i = linear_group() * 256u + gl_LocalInvocationID.x;
    if (i >= p.n) return;
    vec4 c = frame[i];
    c.rgb += (1.0 - clamp(c.a, 0.0, 1.0)) * fill[i / p.per_probe].rgb;
    frame[i] = c;
}
