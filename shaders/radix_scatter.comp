#version 450
// Radix sort pass, step 2: stable scatter. Thread t owns the contiguous run [16t, 16t+16) of its 4096-element block,
// so ranking by (digit, thread, position in run) keeps the input order among equal digits.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = 1) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = 4) readonly buffer Hist { uint hist[]; };
layout(std430, binding = 5) readonly buffer Count { uint count[]; };
// drop = 1: keys equal to drop_key are left out (counted nowhere, written nowhere).
layout(push_constant) uniform P { uint n_blocks; uint shift; uint count_index; uint drop; uint drop_key; } p;
bool dropped(uint key) { return p.drop != 0u && key == p.drop_key; }
shared uint cnt[16 * 256];   // [digit][thread], scanned in place to per-thread offsets within the block
shared uint partial[256];
shared uint digit_start[16];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint block = linear_group();
    if (block >= p.n_blocks) return;
    uint n = count[p.count_index];
    uint base = block * SORT_BLOCK + lid * 16u;
    for (uint d = 0u; d < 16u; ++d) cnt[d * 256u + lid] = 0u;
    uint k[16];
    for (uint i = 0u; i < 16u; ++i) {
        uint idx = base + i;
        k[i] = idx < n ? keys_in[idx] : 0u;
        if (idx < n && !dropped(k[i])) cnt[((k[i] >> p.shift) & 15u) * 256u + lid] += 1u;
    }
    barrier();
    // Exclusive scan of the 4096 counters in [digit][thread] order: thread t scans entries [16t, 16t+16).
    uint run = 0u;
    for (uint i = 0u; i < 16u; ++i) run += cnt[lid * 16u + i];
    partial[lid] = run;
    barrier();
    for (uint off = 1u; off < 256u; off <<= 1) {
        uint add = lid >= off ? partial[lid - off] : 0u;
        barrier();
        partial[lid] += add;
        barrier();
    }
    uint excl = partial[lid] - run;
    barrier();
    for (uint i = 0u; i < 16u; ++i) {
        uint c = cnt[lid * 16u + i];
        cnt[lid * 16u + i] = excl;
        excl += c;
    }
    barrier();
    if (lid < 16u) digit_start[lid] = cnt[lid * 256u];
    barrier();
    for (uint i = 0u; i < 16u; ++i) {
        uint idx = base + i;
        if (idx >= n) break;
        if (dropped(k[i])) continue;
        uint d = (k[i] >> p.shift) & 15u;
        uint slot = cnt[d * 256u + lid];
        cnt[d * 256u + lid] = slot + 1u;
        uint dst = hist[d * p.n_blocks + block] + slot - digit_start[d];
        keys_out[dst] = k[i];
        vals_out[dst] = vals_in[idx];
    }
}
