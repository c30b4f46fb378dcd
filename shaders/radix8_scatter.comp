#version 450
// 8-bit radix pass, step 2: stable scatter of a 4096-key block.
// Ranking, in 32 rounds of 128 keys: within a round, lanes of a subgroup holding the same digit find each other
// with 8 ballots (one per digit bit); subgroups are then ordered by a prefix over their per-digit counts, and
// rounds by a running count, so equal digits keep input order. Each key's rank among the block's keys of its
// digit is kept in shared memory.
// Writing: the block is first reordered by digit in shared memory (keys, then values), and written from there in
// that order, so consecutive lanes write consecutive addresses of a digit's run. Written straight from the
// ranking, a warp's 32 keys went to up to 32 places and the pass was bound by memory transactions (H200,
// docs/benchmarks.md).
// Needs subgroups of at least 8 lanes (lavapipe has 8, NVIDIA 32); the host falls back to 4-bit digits otherwise.
// Shared memory: 26 KiB (lavapipe allows 32).
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
const uint MAX_SG = 16u;             // 128 lanes / 8-lane subgroups
shared uint s_a[SORT_BLOCK];          // ranking: [subgroup][digit] counts, then starts; writing: the reordered block
shared uint s_rank[SORT_BLOCK / 2u];  // per key, its rank within its digit (16 bits; word = two rounds of a lane)
shared uint running[256];             // ranking: keys of each digit so far; then the block's count per digit
shared uint start[256];               // where each digit's keys begin in the reordered block
shared uint part[128];

uint digit_of(uint key) { return (key >> p.shift) & 255u; }

// The digit whose run in the reordered block holds position i: the last with start <= i (empty digits share a
// start with the next one, so they are never the last).
uint digit_at(uint i) {
    uint lo = 0u, hi = 255u;
    while (lo < hi) {
        uint mid = (lo + hi + 1u) >> 1;
        if (start[mid] <= i) lo = mid; else hi = mid - 1u;
    }
    return lo;
}

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    uint n_sg = gl_NumSubgroups;
    uint sg = gl_SubgroupID;
    for (uint s = 0u; s < MAX_SG; ++s) { s_a[s * 256u + lid] = 0u; s_a[s * 256u + lid + 128u] = 0u; }
    running[lid] = 0u;
    running[lid + 128u] = 0u;
    uint base = block * SORT_BLOCK;
    uint rounds = 0u;
    for (uint round = 0u; round < 32u; ++round) {
        uint idx = base + round * 128u + lid;
        if (base + round * 128u >= n) break;  // uniform: the rest of the block is empty
        rounds = round + 1u;
        uint key = idx < n ? keys_in[idx] : 0u;
        bool valid = idx < n && !dropped(key);
        uint d = digit_of(key);
        uvec4 match = subgroupBallot(valid);
        for (uint b = 0u; b < 8u; ++b) {
            bool bit = ((d >> b) & 1u) != 0u;
            uvec4 bb = subgroupBallot(bit);
            match &= bit ? bb : ~bb;
        }
        uint rank = subgroupBallotExclusiveBitCount(match);
        barrier();
        if (valid && rank == 0u) s_a[sg * 256u + d] = subgroupBallotBitCount(match);
        barrier();
        for (uint k = 0u; k < 2u; ++k) {
            uint dd = lid + k * 128u;
            uint run = running[dd];
            for (uint s = 0u; s < n_sg; ++s) {
                uint c = s_a[s * 256u + dd];
                s_a[s * 256u + dd] = run;
                run += c;
            }
            running[dd] = run;
        }
        barrier();
        uint r = valid ? s_a[sg * 256u + d] + rank : 0u;
        uint w = (round >> 1) * 128u + lid;  // this lane's own word: no other lane touches it
        s_rank[w] = (round & 1u) == 0u ? r : (s_rank[w] | (r << 16));
        barrier();
        for (uint s = 0u; s < n_sg; ++s) { s_a[s * 256u + lid] = 0u; s_a[s * 256u + lid + 128u] = 0u; }
    }
    // exclusive scan of the block's 256 digit counts: lane t sums digits 2t, 2t+1, then Hillis-Steele over lanes
    uint c0 = running[2u * lid], c1 = running[2u * lid + 1u];
    part[lid] = c0 + c1;
    barrier();
    for (uint off = 1u; off < 128u; off <<= 1) {
        uint add = lid >= off ? part[lid - off] : 0u;
        barrier();
        part[lid] += add;
        barrier();
    }
    uint excl = part[lid] - c0 - c1;
    start[2u * lid] = excl;
    start[2u * lid + 1u] = excl + c0;
    uint kept = part[127];
    barrier();
    // keys: reordered in shared memory, then written run by run (the keys are read again: 16 KiB, from cache)
    for (uint round = 0u; round < rounds; ++round) {
        uint idx = base + round * 128u + lid;
        if (idx >= n) break;
        uint key = keys_in[idx];
        if (dropped(key)) continue;
        uint r = (s_rank[(round >> 1) * 128u + lid] >> ((round & 1u) * 16u)) & 0xFFFFu;
        s_a[start[digit_of(key)] + r] = key;
    }
    barrier();
    for (uint i = lid; i < kept; i += 128u) {
        uint key = s_a[i];
        uint d = digit_of(key);
        keys_out[hist[d * p.n_blocks + block] + i - start[d]] = key;
    }
    barrier();
    // values: the same places
    for (uint round = 0u; round < rounds; ++round) {
        uint idx = base + round * 128u + lid;
        if (idx >= n) break;
        uint key = keys_in[idx];
        if (dropped(key)) continue;
        uint r = (s_rank[(round >> 1) * 128u + lid] >> ((round & 1u) * 16u)) & 0xFFFFu;
        s_a[start[digit_of(key)] + r] = vals_in[idx];
    }
    barrier();
    for (uint i = lid; i < kept; i += 128u) {
        uint d = digit_at(i);
        vals_out[hist[d * p.n_blocks + block] + i - start[d]] = s_a[i];
    }
}
