"""GPU prefix sum and radix sorts against numpy (exact: integers)."""
import numpy as np
import pytest

from gs_ibl_addon.core.render.gpu_sort import digit_bits_for, exclusive_scan, sort_pairs
from gs_ibl_addon.core.vk import get_context


@pytest.mark.parametrize("n", [1, 1023, 1024, 1025, 3000, 1_100_000])
def test_exclusive_scan(n):
    d = np.random.default_rng(n).integers(0, 40, n).astype(np.uint32)
    out, total = exclusive_scan(get_context(), d)
    np.testing.assert_array_equal(out, np.concatenate([[0], np.cumsum(d)[:-1]]).astype(np.uint32))
    assert total == int(d.sum())


@pytest.mark.parametrize("digit_bits", [4, 8])
@pytest.mark.parametrize("n", [1, 511, 513, 4095, 4096, 4097, 70_000, 200_000, 700_000])
def test_radix_sort_is_a_stable_sort(digit_bits, n):
    ctx = get_context()
    if digit_bits == 8 and digit_bits_for(ctx) != 8:
        pytest.skip(f"{ctx.device_name} has no subgroup ballots of >= 8 lanes: the 8-bit sorter is not used there")
    rng = np.random.default_rng(n)
    keys = rng.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32)
    keys[::3] = keys[0]  # many equal keys: order among them must be kept
    vals = np.arange(n, dtype=np.uint32)
    k, v = sort_pairs(ctx, keys, vals, 32, digit_bits)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(k, keys[order])
    np.testing.assert_array_equal(v, vals[order])


@pytest.mark.parametrize("digit_bits", [4, 8])
def test_sorting_only_the_low_bits(digit_bits):
    ctx = get_context()
    if digit_bits == 8 and digit_bits_for(ctx) != 8:
        pytest.skip("no 8-bit sorter on this device")
    # tile ids: 12 significant bits, not a whole number of 8-bit digits; passes stop after the last one needed
    keys = np.random.default_rng(1).integers(0, 2 ** 12, 20_000).astype(np.uint32)
    vals = np.arange(len(keys), dtype=np.uint32)
    _, v = sort_pairs(ctx, keys, vals, 12, digit_bits)
    np.testing.assert_array_equal(v, np.argsort(keys, kind="stable"))


@pytest.mark.parametrize("digit_bits", [4, 8])
@pytest.mark.parametrize("bits", [5, 12, 23, 32])  # 1-4 passes of 8-bit digits, 2-8 of 4-bit ones
def test_a_sort_left_where_its_last_pass_wrote_it(digit_bits, bits):
    # the renderer's sorts (in_place=False) hand their next stages whichever buffers the last pass wrote: the
    # input's after an even pass count, the sorter's scratch after an odd one (sort_pairs asserts which)
    ctx = get_context()
    if digit_bits == 8 and digit_bits_for(ctx) != 8:
        pytest.skip("no 8-bit sorter on this device")
    keys = np.random.default_rng(bits).integers(0, 2 ** bits, 30_000, dtype=np.uint64).astype(np.uint32)
    keys[::5] = keys[1]
    vals = np.arange(len(keys), dtype=np.uint32)
    k, v = sort_pairs(ctx, keys, vals, bits, digit_bits, in_place=False)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(k, keys[order])
    np.testing.assert_array_equal(v, vals[order])


def test_lavapipe_and_gpus_get_the_8_bit_sorter():
    # every device this project runs on (lavapipe: 8 lanes, NVIDIA: 32) has ballots; a silent fallback would
    # double the sorting passes, so say it if it ever happens
    ctx = get_context()
    assert digit_bits_for(ctx) == 8, (ctx.device_name, ctx.subgroup_size, ctx.subgroup_ballot)


@pytest.mark.parametrize("digit_bits", [4, 8])
@pytest.mark.parametrize("bits", [7, 15])
def test_dropped_keys_leave_the_sort(digit_bits, bits):
    # the tile sort drops instances whose tile the footprint missed (key = one past the last tile): the rest come
    # out packed, stable, and the count says how many
    ctx = get_context()
    if digit_bits == 8 and digit_bits_for(ctx) != 8:
        pytest.skip("no 8-bit sorter on this device")
    rng = np.random.default_rng(bits)
    drop = (1 << bits) - 1
    keys = rng.integers(0, drop + 1, 30_000).astype(np.uint32)
    keys[rng.random(len(keys)) < 0.3] = drop
    vals = np.arange(len(keys), dtype=np.uint32)
    k, v = sort_pairs(ctx, keys, vals, bits, digit_bits, drop_key=drop)
    kept = np.flatnonzero(keys != drop)
    order = kept[np.argsort(keys[kept], kind="stable")]
    np.testing.assert_array_equal(k, keys[order])
    np.testing.assert_array_equal(v, vals[order])


def test_long_sorts_scan_their_histogram():
    # long sorts (4096-key blocks, more than UNSCANNED_MAX_BLOCKS of them: the histogram goes through the scan)
    # give the same stable order and kept count as the short ones the other tests check (512-key blocks, each
    # summing the histogram itself)
    from gs_ibl_addon.core.render.gpu_sort import SHORT_SORT_MAX, UNSCANNED_MAX_BLOCKS
    from gs_ibl_addon.core.vk.constants import SORT_BLOCK
    ctx = get_context()
    n = max(SHORT_SORT_MAX + 1, (UNSCANNED_MAX_BLOCKS + 3) * SORT_BLOCK + 17)
    rng = np.random.default_rng(5)
    keys = rng.integers(0, 1 << 15, n).astype(np.uint32)
    keys[rng.random(n) < 0.2] = (1 << 15) - 1
    vals = np.arange(n, dtype=np.uint32)
    k, v = sort_pairs(ctx, keys, vals, 15, drop_key=(1 << 15) - 1)
    kept = np.flatnonzero(keys != (1 << 15) - 1)
    order = kept[np.argsort(keys[kept], kind="stable")]
    np.testing.assert_array_equal(v, vals[order])
    np.testing.assert_array_equal(k, keys[order])


@pytest.mark.parametrize("short", [False, True])
def test_a_short_list_in_a_large_sorter(monkeypatch, short):
    # a level-of-detail cut: the sorter is sized for the whole tree, the count (on the GPU) is a small part of it
    from gs_ibl_addon.core.render import gpu_sort
    from gs_ibl_addon.core.render.gpu_sort import RadixSorter
    monkeypatch.setattr(gpu_sort, "short_blocks", lambda _ctx, _cap, bits, *_: short and bits == 8)
    from gs_ibl_addon.core.vk import Buffer, Recorder
    ctx = get_context()
    cap, n = 120_000, 13_001
    rng = np.random.default_rng(9)
    keys = rng.integers(0, 2 ** 32, cap, dtype=np.uint64).astype(np.uint32)
    kb, vb, cb = Buffer(ctx, cap * 4, "k"), Buffer(ctx, cap * 4, "v"), Buffer(ctx, 16, "c")
    kb.write(keys)
    vb.write(np.arange(cap, dtype=np.uint32))
    cb.write(np.array([0, n, 0, 0], np.uint32))
    sorter = RadixSorter(ctx, cap)
    with Recorder(ctx) as rec:
        sorter.record(rec, kb, vb, cb, 1, 32)
    order = np.argsort(keys[:n], kind="stable")
    np.testing.assert_array_equal(vb.read(np.uint32, n), order)
    np.testing.assert_array_equal(kb.read(np.uint32, n), keys[:n][order])
    sorter.destroy()
    for b in (kb, vb, cb):
        b.destroy()


@pytest.mark.parametrize("short", [False, True])
@pytest.mark.parametrize("coalesce", [0, 1])
@pytest.mark.parametrize("n", [3001, 600_001])
def test_both_ways_of_writing_a_block(monkeypatch, coalesce, n, short):
    # radix8_scatter writes a block from shared memory digit by digit (the default) or each key from its register;
    # both are the same stable sort, with dropped keys left out, in short blocks and long ones, unscanned (few
    # blocks) and scanned
    from gs_ibl_addon.core.render import gpu_sort
    ctx = get_context()
    if digit_bits_for(ctx) != 8:
        pytest.skip("no 8-bit sorter on this device")
    monkeypatch.setattr(gpu_sort, "COALESCE", coalesce)
    # 512-key blocks (GPUs: short sorts and level-of-detail cuts) or 4096-key ones, whatever this device would use
    monkeypatch.setattr(gpu_sort, "short_blocks", lambda _ctx, _cap, bits, *_: short and bits == 8)
    rng = np.random.default_rng(n + coalesce)
    keys = rng.integers(0, 1 << 20, n).astype(np.uint32)
    keys[rng.random(n) < 0.1] = 77
    keys[rng.random(n) < 0.1] = 5
    vals = rng.permutation(n).astype(np.uint32)
    k, v = sort_pairs(ctx, keys, vals, 20, drop_key=77)
    kept = np.flatnonzero(keys != 77)
    order = kept[np.argsort(keys[kept], kind="stable")]
    np.testing.assert_array_equal(k, keys[order])
    np.testing.assert_array_equal(v, vals[order])


@pytest.mark.parametrize("digit_bits", [4, 8])
def test_a_sort_recorded_for_fewer_pairs_than_its_capacity(digit_bits):
    """RadixSorter.record(n=...): a large sorter given a short list dispatches that list's blocks only, and sorts
    it as a sorter of its own size would (odd and even pass counts, with and without dropping a key)."""
    from gs_ibl_addon.core.render.gpu_sort import RadixSorter
    from gs_ibl_addon.core.vk import Buffer, Recorder
    ctx = get_context()
    if digit_bits == 8 and digit_bits_for(ctx) != 8:
        pytest.skip("no 8-bit sorter on this device")
    capacity, n = 300_000, 9_000
    sorter = RadixSorter(ctx, capacity, digit_bits)
    kb, vb, cb = Buffer(ctx, capacity * 4, "k"), Buffer(ctx, capacity * 4, "v"), Buffer(ctx, 16, "count")
    try:
        for bits, drop in ((32, None), (12, 7), (20, None)):
            rng = np.random.default_rng(bits)
            keys = rng.integers(0, 2 ** bits, n, dtype=np.uint64).astype(np.uint32)
            keys[::5] = 7
            vals = np.arange(n, dtype=np.uint32)
            kb.write(np.concatenate([keys, np.full(capacity - n, 2 ** bits - 1, np.uint32)]))
            vb.write(np.arange(capacity, dtype=np.uint32))
            cb.write(np.array([n, 0, 0, 0], np.uint32))
            with Recorder(ctx) as rec:
                sorter.record(rec, kb, vb, cb, 0, bits, drop_key=drop, n=n + 100)
            kept = keys != drop if drop is not None else np.ones(n, bool)
            order = np.argsort(keys[kept], kind="stable")
            assert int(cb.read(np.uint32, 1)[0]) == kept.sum()
            np.testing.assert_array_equal(kb.read(np.uint32, n)[:kept.sum()], keys[kept][order])
            np.testing.assert_array_equal(vb.read(np.uint32, n)[:kept.sum()], vals[kept][order])
    finally:
        sorter.destroy()
        for b in (kb, vb, cb):
            b.destroy()
