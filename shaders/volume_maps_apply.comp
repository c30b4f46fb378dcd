#version 450
// The light volume's maps, step 2 of 2 (probe/gpu_volume_maps.py): out = M x in per probe, M a fixed (rows, n_in)
// matrix stored transposed (n_in, rows) (volume_bake.irradiance_matrix / visibility_matrix and one more row, a
// plain sum), in (n_in) vec4 per probe from volume_maps_prep. Rows 0..rows-2 write `channels` floats each, the last
// row writes its channel `extra` (the hole or closeness fraction) after them; probe q's results at q * stride + at,
// so both maps and both fractions of a probe land in one small buffer read back once.
// A workgroup: 64 rows x PROBES probes, the probes' inputs staged in shared memory 64 at a time (each matrix entry
// read once for PROBES probes).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#define PROBES 4u
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Matrix { float m[]; };
layout(std430, binding = 1) readonly buffer In { vec4 x[]; };
layout(std430, binding = 2) writeonly buffer Out { float o[]; };
layout(push_constant) uniform P { uint n_in; uint rows; uint probes; uint channels; uint stride; uint at; uint extra; } p;

shared vec4 tile[PROBES][64];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint row = gl_WorkGroupID.x * 64u + lid, p0 = gl_WorkGroupID.y * PROBES;
    vec4 acc[PROBES];
    for (uint q = 0u; q < PROBES; ++q) acc[q] = vec4(0.0);
    for (uint j0 = 0u; j0 < p.n_in; j0 += 64u) {
        barrier();
        for (uint q = 0u; q < PROBES; ++q) {
            uint pr = p0 + q, j = j0 + lid;
            tile[q][lid] = (pr < p.probes && j < p.n_in) ? x[pr * p.n_in + j] : vec4(0.0);
        }
        barrier();
        if (row < p.rows) {
            uint jn = min(64u, p.n_in - j0);
            for (uint jj = 0u; jj < jn; ++jj) {
                float w = m[(j0 + jj) * p.rows + row];
                for (uint q = 0u; q < PROBES; ++q) acc[q] += w * tile[q][jj];
            }
        }
    }
    if (row >= p.rows) return;
    for (uint q = 0u; q < PROBES; ++q) {
        uint pr = p0 + q;
        if (pr >= p.probes) break;
        uint base = pr * p.stride + p.at;
        if (row + 1u == p.rows) {
            o[base + row * p.channels] = acc[q][p.extra];
        } else {
            for (uint c = 0u; c < p.channels; ++c) o[base + row * p.channels + c] = acc[q][c];
        }
    }
}
