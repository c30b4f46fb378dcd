#version 450
// 8-bit radix pass, step 2: stable scatter of a 4096-key block. Each subgroup ranks its own contiguous share of
// the block (32 rounds of one key per lane) with no workgroup barrier in between: lanes holding the same digit find
// each other with 8 ballots (one per digit bit), and a per-subgroup count per digit orders the rounds. Then one
// prefix per digit over the subgroups, added to the block's offset from the scanned histogram, places every key:
// equal digits keep input order (subgroup, then round, then lane). Ranks wait in shared memory (16 bits each).
// (An earlier version ranked all 128 lanes together, four workgroup barriers per round of 128 keys; on an H200 the
// barriers, not the scattered writes, bounded it: docs/benchmarks.md.)
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
const uint MAX_SG = 16u;                // 128 lanes / 8-lane subgroups
shared uint cnt[MAX_SG * 256u];         // [subgroup][digit]: its keys of the digit so far, then where they go
shared uint s_rank[SORT_BLOCK / 2u];    // two rounds of one lane per word: no other lane touches it

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    uint n_sg = gl_NumSubgroups, sg = gl_SubgroupID, lane = gl_SubgroupInvocationID, w = gl_SubgroupSize;
    for (uint s = 0u; s < n_sg; ++s) { cnt[s * 256u + lid] = 0u; cnt[s * 256u + lid + 128u] = 0u; }
    barrier();
    uint sub = block * SORT_BLOCK + sg * 32u * w;  // this subgroup's share: 32 rounds of w keys
    uint rounds = 0u;
    for (uint round = 0u; round < 32u; ++round) {
        if (sub + round * w >= n) break;  // uniform in the subgroup: the rest of its share is empty
        rounds = round + 1u;
        uint idx = sub + round * w + lane;
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
        uint before = valid ? cnt[sg * 256u + d] : 0u;
        subgroupMemoryBarrierShared();
        subgroupBarrier();  // every lane has read its digit's count before the digit's first lane moves it on
        if (valid && rank == 0u) cnt[sg * 256u + d] = before + subgroupBallotBitCount(match);
        subgroupMemoryBarrierShared();
        subgroupBarrier();
        uint r = before + rank;
        uint word = (sg * 16u + (round >> 1)) * w + lane;
        s_rank[word] = (round & 1u) == 0u ? r : (s_rank[word] | (r << 16));
    }
    barrier();
    // per digit: this block's first place (the scanned histogram), then each subgroup's share after the previous
    for (uint k = 0u; k < 2u; ++k) {
        uint dd = lid + k * 128u;
        uint run = hist[dd * p.n_blocks + block];
        for (uint s = 0u; s < n_sg; ++s) {
            uint c = cnt[s * 256u + dd];
            cnt[s * 256u + dd] = run;
            run += c;
        }
    }
    barrier();
    for (uint round = 0u; round < rounds; ++round) {
        uint idx = sub + round * w + lane;
        if (idx >= n) break;
        uint key = keys_in[idx];  // read again: 16 KiB per block, from cache
        if (dropped(key)) continue;
        uint r = (s_rank[(sg * 16u + (round >> 1)) * w + lane] >> ((round & 1u) * 16u)) & 0xFFFFu;
        uint dst = cnt[sg * 256u + ((key >> p.shift) & 255u)] + r;
        keys_out[dst] = key;
        vals_out[dst] = vals_in[idx];
    }
}
