#version 450
// 8-bit radix pass, step 2: stable scatter of a block of block_rounds x 128 keys, 256 lanes holding block_rounds / 2
// keys each (16 for 4096-key blocks). Each subgroup owns a contiguous run of the block and ranks its keys one
// register at a time (a warp-level multisplit): lanes holding the same digit find each other with 8 ballots, and a
// per-subgroup count per digit (16-bit halves of shared words) says how many of that digit the subgroup has seen.
// One barrier-separated scan over subgroups then orders the subgroups, so equal digits keep input order. The
// earlier kernel ranked 128 keys per round with three workgroup barriers each, 32 rounds in a row: the dependent
// rounds, not the memory traffic, bounded it (docs/benchmarks.md).
// coalesce = 1: the block is reordered by digit in shared memory first and each digit's run is written by
// consecutive lanes; 0: every key goes straight from its register to its place.
// scanned = 0 (sorts of at most a few hundred blocks): the histogram is not scanned; every block sums the counts
// before it itself, and block 0 writes the number of keys kept after the histogram (hist[256 * n_blocks]).
// Needs subgroups of 8..128 lanes (lavapipe has 8, NVIDIA 32); the host falls back to 4-bit digits otherwise.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_EXT_control_flow_attributes : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = 1) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = 4) buffer Hist { uint hist[]; };
layout(std430, binding = 5) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key;
    uint block_rounds;  // the block is block_rounds x 128 keys (as radix8_hist counts it): 32 or fewer, even
    uint scanned;
    uint coalesce;
} p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
const uint MAX_KPT = 16u;           // keys per lane: 4096-key blocks
const uint MAX_SG = 32u;            // 256 lanes / 8-lane subgroups
const uint NONE = 0xFFFFFFFFu;
// [subgroup][digit pair]: 16-bit counts, then each subgroup's start within the digit; later the reorder buffer
shared uint pool[MAX_SG * 128u];    // = 256 x MAX_KPT uints
shared uint first[256];             // where this block's keys of each digit begin in the output
shared uint local_first[256];       // where they begin within the block, digits in order
shared uint part[128];

// Exclusive scan of 2 values per lane over the first 128 lanes (digits 2t, 2t + 1); returns the grand total.
uint scan_pairs(uint lid, uint a, uint b, out uint excl) {
    if (lid < 128u) part[lid] = a + b;
    barrier();
    for (uint off = 1u; off < 128u; off <<= 1) {
        uint add = (lid < 128u && lid >= off) ? part[lid - off] : 0u;
        barrier();
        if (lid < 128u) part[lid] += add;
        barrier();
    }
    excl = lid < 128u ? part[lid] - a - b : 0u;
    uint total = part[127];
    barrier();
    return total;
}

// first[] from the unscanned histogram: all blocks' counts give each digit's start, the blocks before this one
// its place within the digit. Only blocks that hold keys are summed (the others' counts are 0).
void offsets_from_counts(uint lid, uint block, uint n, uint block_keys) {
    uint tot0 = 0u, tot1 = 0u, before0 = 0u, before1 = 0u;
    if (lid < 128u) {
        uint r0 = (2u * lid) * p.n_blocks, r1 = r0 + p.n_blocks;
        uint used = min(p.n_blocks, (n + block_keys - 1u) / block_keys);
        for (uint b = 0u; b < used; ++b) {
            uint h0 = hist[r0 + b], h1 = hist[r1 + b];
            tot0 += h0; tot1 += h1;
            if (b < block) { before0 += h0; before1 += h1; }
        }
    }
    uint excl;
    uint total = scan_pairs(lid, tot0, tot1, excl);
    if (lid < 128u) {
        first[2u * lid] = excl + before0;
        first[2u * lid + 1u] = excl + tot0 + before1;
    }
    if (block == 0u && lid == 0u) hist[256u * p.n_blocks] = total;
}

uint half_of(uint word, uint d) { return (word >> ((d & 1u) * 16u)) & 0xFFFFu; }

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    uint kpt = p.block_rounds / 2u;
    uint block_keys = kpt * 256u;
    uint base = block * block_keys;
    if (base >= n && block != 0u) return;  // uniform; block 0 still writes the kept count when unscanned
    if (p.scanned != 0u) {
        first[lid] = hist[lid * p.n_blocks + block];
    } else {
        offsets_from_counts(lid, block, n, block_keys);
    }
    uint n_sg = gl_NumSubgroups, sg = gl_SubgroupID, sgs = gl_SubgroupSize, lane = gl_SubgroupInvocationID;
    for (uint j = lid; j < n_sg * 128u; j += 256u) pool[j] = 0u;
    barrier();

    // Rank: key i of this lane is input key sg_base + i * sgs + lane; rank[i] its place among this subgroup's
    // keys of its digit (NONE: no key).
    uint sg_base = base + sg * sgs * kpt;
    uint keys[MAX_KPT];
    uint rank[MAX_KPT];
    [[unroll]] for (uint i = 0u; i < MAX_KPT; ++i) {
        rank[i] = NONE;
        keys[i] = 0u;
        if (i < kpt) {
            uint idx = sg_base + i * sgs + lane;
            uint key = idx < n ? keys_in[idx] : 0u;
            bool valid = idx < n && !dropped(key);
            uint d = (key >> p.shift) & 255u;
            uvec4 match = subgroupBallot(valid);
            for (uint b = 0u; b < 8u; ++b) {
                bool bit = ((d >> b) & 1u) != 0u;
                uvec4 bb = subgroupBallot(bit);
                match &= bit ? bb : ~bb;
            }
            uint word = sg * 128u + (d >> 1);
            uint before = half_of(pool[word], d);
            subgroupMemoryBarrierShared();
            subgroupBarrier();  // every lane has read its digit's count before the leaders add to it
            uint lt = subgroupBallotExclusiveBitCount(match);
            if (valid && lt == 0u) atomicAdd(pool[word], subgroupBallotBitCount(match) << ((d & 1u) * 16u));
            subgroupMemoryBarrierShared();
            subgroupBarrier();
            keys[i] = key;
            if (valid) rank[i] = before + lt;
        }
    }
    barrier();

    // Order the subgroups: lane t < 128 turns digits 2t, 2t + 1's counts into each subgroup's start within the
    // block's run of that digit, and the totals into where each digit's run begins in the block.
    uint tot0 = 0u, tot1 = 0u;
    if (lid < 128u) {
        for (uint s = 0u; s < n_sg; ++s) {
            uint w = pool[s * 128u + lid];
            pool[s * 128u + lid] = tot0 | (tot1 << 16);
            tot0 += w & 0xFFFFu;
            tot1 += w >> 16;
        }
    }
    uint excl;
    uint kept = scan_pairs(lid, tot0, tot1, excl);
    if (lid < 128u) {
        local_first[2u * lid] = excl;
        local_first[2u * lid + 1u] = excl + tot0;
    }
    barrier();
    [[unroll]] for (uint i = 0u; i < MAX_KPT; ++i) {
        if (rank[i] != NONE) {
            uint d = (keys[i] >> p.shift) & 255u;
            rank[i] += half_of(pool[sg * 128u + (d >> 1)], d);  // now the key's place within its digit's run
        }
    }

    if (p.coalesce == 0u) {
        [[unroll]] for (uint i = 0u; i < MAX_KPT; ++i) {
            if (rank[i] != NONE) {
                uint dst = first[(keys[i] >> p.shift) & 255u] + rank[i];
                keys_out[dst] = keys[i];
                vals_out[dst] = vals_in[sg_base + i * sgs + lane];
            }
        }
        return;
    }
    barrier();  // the counts are read: the pool becomes the block, digit by digit
    [[unroll]] for (uint i = 0u; i < MAX_KPT; ++i) {
        if (rank[i] != NONE) pool[local_first[(keys[i] >> p.shift) & 255u] + rank[i]] = keys[i];
    }
    barrier();
    uint dst[MAX_KPT];
    [[unroll]] for (uint j = 0u; j < MAX_KPT; ++j) {
        uint at = j * 256u + lid;
        dst[j] = NONE;
        if (j < kpt && at < kept) {
            uint key = pool[at];
            uint d = (key >> p.shift) & 255u;
            dst[j] = first[d] + at - local_first[d];
            keys_out[dst[j]] = key;
        }
    }
    barrier();
    [[unroll]] for (uint i = 0u; i < MAX_KPT; ++i) {
        if (rank[i] != NONE) pool[local_first[(keys[i] >> p.shift) & 255u] + rank[i]] = vals_in[sg_base + i * sgs + lane];
    }
    barrier();
    [[unroll]] for (uint j = 0u; j < MAX_KPT; ++j) {
        if (dst[j] != NONE) vals_out[dst[j]] = pool[j * 256u + lid];
    }
}
