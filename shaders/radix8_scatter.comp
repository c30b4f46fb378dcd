#version 450
// 8-bit radix pass, step 2: stable scatter of a block in block_rounds rounds of 128 keys. Within a round, lanes of a
// subgroup holding the same digit find each other with 8 ballots (one per digit bit); subgroups are then ordered
// by a prefix over their per-digit counts, and rounds by a running count, so equal digits keep input order.
// scanned = 0 (sorts of at most a few hundred blocks): the histogram is not scanned; every block sums the counts
// before it itself (a 256 x n_blocks read from cache), which saves the scan's two or three dispatches and their
// barriers per pass: most of a short sort's time. Block 0 then also writes the number of keys kept after the
// histogram (hist[256 * n_blocks]), where the scan would have put its total.
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
layout(std430, binding = 4) buffer Hist { uint hist[]; };
layout(std430, binding = 5) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key;
    uint block_rounds;  // rounds of 128 keys per block: 32 (SORT_BLOCK keys), fewer for short sorts
    uint scanned;
} p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
const uint MAX_SG = 16u;            // 128 lanes / 8-lane subgroups
shared uint sg_count[MAX_SG * 256u]; // [subgroup][digit]: count in this round, then that subgroup's start
shared uint running[256];            // keys of each digit already placed from earlier rounds of this block
shared uint first[256];              // where this block's keys of each digit begin in the output
shared uint part[128];

// first[] from the unscanned histogram: lane t owns digits 2t and 2t + 1; all blocks' counts give each digit's
// start (a scan over digits), the blocks before this one its place within the digit.
// Only blocks that hold keys are summed (the others' counts are 0): a short list in a large sorter reads little.
void offsets_from_counts(uint lid, uint block, uint n) {
    uint tot0 = 0u, tot1 = 0u, before0 = 0u, before1 = 0u;
    uint r0 = (2u * lid) * p.n_blocks, r1 = r0 + p.n_blocks;
    uint used = min(p.n_blocks, (n + p.block_rounds * 128u - 1u) / (p.block_rounds * 128u));
    for (uint b = 0u; b < used; ++b) {
        uint h0 = hist[r0 + b], h1 = hist[r1 + b];
        tot0 += h0; tot1 += h1;
        if (b < block) { before0 += h0; before1 += h1; }
    }
    part[lid] = tot0 + tot1;
    barrier();
    for (uint off = 1u; off < 128u; off <<= 1) {
        uint add = lid >= off ? part[lid - off] : 0u;
        barrier();
        part[lid] += add;
        barrier();
    }
    uint excl = part[lid] - tot0 - tot1;
    first[2u * lid] = excl + before0;
    first[2u * lid + 1u] = excl + tot0 + before1;
    if (block == 0u && lid == 127u) hist[256u * p.n_blocks] = part[127];
}

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    if (p.scanned != 0u) {
        first[lid] = hist[lid * p.n_blocks + block];
        first[lid + 128u] = hist[(lid + 128u) * p.n_blocks + block];
    } else {
        offsets_from_counts(lid, block, n);
    }
    uint n_sg = gl_NumSubgroups;
    uint sg = gl_SubgroupID;
    for (uint s = 0u; s < MAX_SG; ++s) { sg_count[s * 256u + lid] = 0u; sg_count[s * 256u + lid + 128u] = 0u; }
    running[lid] = 0u;
    running[lid + 128u] = 0u;
    uint base = block * p.block_rounds * 128u;
    for (uint round = 0u; round < p.block_rounds; ++round) {
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
            uint dst = first[d] + sg_count[sg * 256u + d] + rank;
            keys_out[dst] = key;
            vals_out[dst] = vals_in[idx];
        }
        barrier();
        for (uint s = 0u; s < n_sg; ++s) { sg_count[s * 256u + lid] = 0u; sg_count[s * 256u + lid + 128u] = 0u; }
    }
}
