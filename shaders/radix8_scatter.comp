#version 450
// 8-bit radix pass, step 2: stable scatter of a 4096-key block in 32 rounds of 128 keys. Within a round, lanes of a
// subgroup holding the same digit find each other with 8 ballots (one per digit bit); subgroups are then ordered
// by a prefix over their per-digit counts, and rounds by a running count, so equal digits keep input order.
// Needs subgroups of at least 8 lanes (lavapipe has 8, NVIDIA 32); the host falls back to 4-bit digits otherwise.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "common.glsl"
layout(local_size_x = 128) in;
layout(std430, binding = 0) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = 1) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = 4) readonly buffer Hist { uint hist[]; };
layout(std430, binding = 5) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key; } p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
const uint MAX_SG = 16u;            // 128 lanes / 8-lane subgroups
shared uint sg_count[MAX_SG * 256u]; // [subgroup][digit]: count in this round, then that subgroup's start
shared uint running[256];            // keys of each digit already placed from earlier rounds of this block

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    uint n_sg = gl_NumSubgroups;
    uint sg = gl_SubgroupID;
    for (uint s = 0u; s < MAX_SG; ++s) { sg_count[s * 256u + lid] = 0u; sg_count[s * 256u + lid + 128u] = 0u; }
    running[lid] = 0u;
    running[lid + 128u] = 0u;
    uint base = block * SORT_BLOCK;
    for (uint round = 0u; round < 32u; ++round) {
        uint idx = base + round * 128u + lid;
        if (base + round * 128u >= n) break;  // uniform: the rest of the block is empty
        uint key = idx < n ? keys_in[idx] : 0u;
        bool valid = idx < n && !dropped(key);
        uint d = (key >> p.shift) & 255u;
        uvec4 match = subgroupBallot(valid);
        for (uint b = 0u; b < 8u; ++b) {
            bool bit = ((d >> b) & 1u) != 0u;
            uvec4 bb = subgroupBallot(bit);
            match &= bit ? bb : ~bb;
        }
        uint rank = subgroupBallotExclusiveBitCount(match);
        barrier();
        if (valid && rank == 0u) sg_count[sg * 256u + d] = subgroupBallotBitCount(match);
        barrier();
        for (uint k = 0u; k < 2u; ++k) {
            uint dd = lid + k * 128u;
            uint run = running[dd];
            for (uint s = 0u; s < n_sg; ++s) {
                uint c = sg_count[s * 256u + dd];
                sg_count[s * 256u + dd] = run;
                run += c;
            }
            running[dd] = run;
        }
        barrier();
        if (valid) {
            uint dst = hist[d * p.n_blocks + block] + sg_count[sg * 256u + d] + rank;
            keys_out[dst] = key;
            vals_out[dst] = vals_in[idx];
        }
        barrier();
        for (uint s = 0u; s < n_sg; ++s) { sg_count[s * 256u + lid] = 0u; sg_count[s * 256u + lid + 128u] = 0u; }
    }
}
