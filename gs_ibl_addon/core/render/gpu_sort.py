"""GPU prefix sum and stable LSD radix sort (8-bit digits with subgroup ballots, else 4-bit) of uint32 key/value
pairs, recorded into a Recorder.

Counts may live on the GPU (``count`` buffer), so a sort of a GPU-sized list needs no read-back: work is dispatched
for a known capacity and blocks past the count return at once.
"""
from __future__ import annotations

import numpy as np

from ..vk import Buffer, Recorder
from ..vk import groups
from ..vk.constants import SCAN_BLOCK, SORT_BLOCK
from ..vk.kernels import KERNELS


class Scanner:
    """Exclusive prefix sums of up to ``capacity`` uints; scratch buffers are kept for reuse."""

    def __init__(self, ctx, capacity: int) -> None:
        self.ctx = ctx
        self.levels: list[tuple[int, Buffer]] = []  # (length of the level being scanned, its block-sums buffer)
        n = max(1, int(capacity))
        while True:
            nb = -(-n // SCAN_BLOCK)
            self.levels.append((n, Buffer(ctx, nb * 4, f"scan-sums-{len(self.levels)}")))
            if nb == 1:
                break
            n = nb
        self.capacity = int(capacity)

    def record(self, rec: Recorder, data: Buffer, n: int) -> Buffer:
        """Scan ``data[:n]`` in place; returns the buffer whose first uint is the grand total."""
        if n > self.capacity:
            raise ValueError(f"scan of {n} > capacity {self.capacity}")
        blk, add = KERNELS["scan_block"], KERNELS["scan_add"]
        chain = []
        cur, length = data, max(1, int(n))
        for _, sums in self.levels:
            rec.dispatch(blk, [cur, sums], groups(length, SCAN_BLOCK, self.ctx), n=length)
            chain.append((cur, sums, length))
            nb = -(-length // SCAN_BLOCK)
            if nb == 1:
                break
            cur, length = sums, nb
        for cur, sums, length in reversed(chain[:-1]):
            rec.dispatch(add, [cur, sums], groups(length, SCAN_BLOCK, self.ctx), n=length)
        return chain[-1][1]

    def destroy(self) -> None:
        for _, b in self.levels:
            b.destroy()


def digit_bits_for(ctx) -> int:
    """8-bit digits (half the passes) where subgroup ballots of >= 8 lanes exist, else 4-bit digits."""
    return 8 if ctx.subgroup_ballot and 8 <= ctx.subgroup_size <= 128 else 4


# Sorts of at most this many blocks skip the histogram's scan: each scatter block sums the counts before it
# (radix8_scatter.comp, scanned = 0), and a pass is two dispatches instead of four or five. Measured on an H200
# (docs/benchmarks.md): a 100k-key depth sort (25 blocks of 4096) 0.19 -> 0.15 ms; at 245 blocks of 4096 (1M keys)
# summing cost more than the scan saved (0.22 -> 0.28 ms), so long blocks go unscanned only up to 128 of them.
UNSCANNED_MAX_BLOCKS = 128
UNSCANNED_MAX_SHORT_BLOCKS = 256  # 512-key blocks: each block sums only the blocks that hold keys
# A short sort costs what its blocks' latency does, so sorts of up to SHORT_SORT_MAX keys (and sorters told their
# lists are usually far shorter than their capacity: a level-of-detail cut) use blocks of SHORT_BLOCK_ROUNDS x 128
# keys (512) instead of 32 x 128. Measured on an H200 with radix8_scatter ranking 16 keys a lane (2026-12-03,
# sort_bench): 13k keys 0.064 ms short, 0.092 long; 100k keys 0.141 short, 0.107 long.
SHORT_SORT_MAX = 1 << 15
SHORT_BLOCK_ROUNDS = 4
# radix8_scatter writes a block digit by digit from shared memory (1) or each key from its register (0).
COALESCE = 1


def short_blocks(ctx, capacity: int, digit_bits: int, short_lists: bool = False) -> bool:
    """Whether a sorter for ``capacity`` keys uses 512-key blocks. Not on a CPU device: it runs a block's lanes one
    after another, and a short block's fixed cost (zeroing, scans, summing the counts of every block before it)
    is all it would save there (lavapipe, 100k keys: 183 ms with short blocks, 47 ms with long ones)."""
    return digit_bits == 8 and (short_lists or capacity <= SHORT_SORT_MAX) and not getattr(ctx, "is_cpu", False)


class RadixSorter:
    """Stable sort of (key, value) uint32 pairs by the low ``bits`` bits of the key, for up to ``capacity`` pairs.

    ``digit_bits`` 8 uses shaders/radix8_*.comp (subgroup ballots); 4 uses shaders/radix_*.comp (no subgroups).
    ``short_lists``: the counts it sorts are usually a small part of ``capacity`` (short blocks on a GPU).
    """

    def __init__(self, ctx, capacity: int, digit_bits: int | None = None, short_lists: bool = False) -> None:
        self.ctx = ctx
        self.digit_bits = digit_bits or digit_bits_for(ctx)
        if self.digit_bits not in (4, 8):
            raise ValueError(f"radix digits are 4 or 8 bits, not {self.digit_bits}")
        self.bins = 1 << self.digit_bits
        self.capacity = max(1, int(capacity))
        self.block_rounds = SHORT_BLOCK_ROUNDS if short_blocks(ctx, self.capacity, self.digit_bits, short_lists) else 32
        self.block_keys = SORT_BLOCK if self.digit_bits != 8 else 128 * self.block_rounds
        self.n_blocks = -(-self.capacity // self.block_keys)
        self.keys_tmp = Buffer(ctx, self.capacity * 4, "sort-keys-tmp")
        self.vals_tmp = Buffer(ctx, self.capacity * 4, "sort-vals-tmp")
        self.hist = Buffer(ctx, self.bins * self.n_blocks * 4 + 4, "sort-hist")  # + the kept count (unscanned)
        self.scanner = Scanner(ctx, self.bins * self.n_blocks)

    def record(self, rec: Recorder, keys: Buffer, vals: Buffer, count: Buffer, count_index: int, bits: int,
               drop_key: int | None = None, stamps: str | None = None, n: int | None = None,
               in_place: bool = True) -> tuple[Buffer, Buffer]:
        """Sort; returns the (keys, values) buffers the result is in. ``in_place``: always ``keys``/``vals`` (an odd
        pass count then costs a copy of both); else whichever the last pass wrote, ``keys``/``vals`` or this
        sorter's scratch buffers (valid until its next recorded sort runs).

        ``n``: the most pairs ``count`` may hold for this recording (default the capacity): blocks past it are not
        dispatched, so a short list in a large sorter costs what its own blocks do. A count past ``n`` sorts only
        the first ``n`` pairs (the renderer sees that after the frame and draws it again).

        ``drop_key``: pairs with exactly this key are left out of the result, which is then packed at the front,
        and ``count[count_index]`` becomes the number kept (the first pass's histogram total): the later passes,
        and whoever reads the count, see only those. ``stamps``: a label prefix for a timestamp after each step
        (``<prefix>.hist``, ``.scan``, ``.scatter``; benchmarks only, they split the sort's time).
        """
        prefix = "radix8" if self.digit_bits == 8 else "radix"
        hist_k, scat_k = KERNELS[f"{prefix}_hist"], KERNELS[f"{prefix}_scatter"]
        n = self.capacity if n is None else max(1, min(int(n), self.capacity))
        n_blocks = -(-n // self.block_keys)
        g = groups(n_blocks, 1, self.ctx)
        src_k, src_v, dst_k, dst_v = keys, vals, self.keys_tmp, self.vals_tmp
        passes = max(1, -(-int(bits) // self.digit_bits))
        short = self.digit_bits == 8 and self.block_rounds == SHORT_BLOCK_ROUNDS
        scan = self.digit_bits != 8 or n_blocks > (UNSCANNED_MAX_SHORT_BLOCKS if short else UNSCANNED_MAX_BLOCKS)

        def stamp(step: str) -> None:
            if stamps:
                rec.timestamp(f"{stamps}.{step}")
        for i in range(passes):
            drop = i == 0 and drop_key is not None
            push = {"n_blocks": n_blocks, "shift": self.digit_bits * i, "count_index": count_index,
                    "drop": int(drop), "drop_key": int(drop_key or 0)}
            if self.digit_bits == 8:  # the 8-bit kernels' blocks, and how the scatter reads and writes them
                push["block_rounds"] = self.block_rounds
            rec.dispatch(hist_k, [src_k, self.hist, count], g, **push)
            stamp("hist")
            if scan:
                total, total_at = self.scanner.record(rec, self.hist, self.bins * n_blocks), 0
                stamp("scan")
            else:
                total, total_at = self.hist, 4 * self.bins * n_blocks
            scatter_push = push if self.digit_bits != 8 else dict(push, scanned=int(scan), coalesce=COALESCE)
            rec.dispatch(scat_k, [src_k, src_v, dst_k, dst_v, self.hist, count], g, **scatter_push)
            if drop:  # the histogram's total is what the first pass kept
                rec.copy(total, count, 4, src_offset=total_at, dst_offset=4 * count_index)
            stamp("scatter")
            src_k, src_v, dst_k, dst_v = dst_k, dst_v, src_k, src_v
        if in_place and src_k is not keys:
            rec.copy(src_k, keys, n * 4)
            rec.copy(src_v, vals, n * 4)
            stamp("copy")
            src_k, src_v = keys, vals
        return src_k, src_v

    def destroy(self) -> None:
        for b in (self.keys_tmp, self.vals_tmp, self.hist):
            b.destroy()
        self.scanner.destroy()


def sort_pairs(ctx, keys: np.ndarray, vals: np.ndarray, bits: int = 32, digit_bits: int | None = None,
               drop_key: int | None = None, in_place: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Convenience for tests: sort host arrays on the GPU (pairs with key ``drop_key`` left out), read back from
    the buffers the sorter says hold the result."""
    n = len(keys)
    kb, vb = Buffer(ctx, n * 4, "k"), Buffer(ctx, n * 4, "v")
    cb = Buffer(ctx, 16, "count")
    kb.write(keys.astype(np.uint32))
    vb.write(vals.astype(np.uint32))
    cb.write(np.array([n, 0, 0, 0], np.uint32))
    sorter = RadixSorter(ctx, n, digit_bits)
    with Recorder(ctx) as rec:
        rk, rv = sorter.record(rec, kb, vb, cb, 0, bits, drop_key, in_place=in_place)
    passes = -(-int(bits) // sorter.digit_bits)
    assert (rk is kb) == (in_place or passes % 2 == 0) and (rk is kb) == (rv is vb)
    kept = int(cb.read(np.uint32, 1)[0])
    out = rk.read(np.uint32, n)[:kept], rv.read(np.uint32, n)[:kept]
    sorter.destroy()
    for b in (kb, vb, cb):
        b.destroy()
    return out


def exclusive_scan(ctx, data: np.ndarray) -> tuple[np.ndarray, int]:
    """Convenience for tests: exclusive scan of a host array on the GPU; returns (scan, total)."""
    n = len(data)
    b = Buffer(ctx, n * 4, "scan-data")
    b.write(data.astype(np.uint32))
    sc = Scanner(ctx, n)
    with Recorder(ctx) as rec:
        tot_buf = sc.record(rec, b, n)
    out = b.read(np.uint32, n)
    total = int(tot_buf.read(np.uint32, 1)[0])
    sc.destroy()
    b.destroy()
    return out, total
