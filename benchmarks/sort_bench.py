"""Our GPU radix sort against torch's (CUB) on the same keys, one process, one GPU (issue 24).

Two workloads, the renderer's two sorts at 6M splats / 1024² faces:
  depth  N keys of 32 bits (a depth key and its tie hash: four 8-bit passes), values 0..N-1
  tiles  M keys of 15 bits (tile ids: two passes), 9% of them the dropped key (a footprint that missed its tile)
Ours: RadixSorter.record in one command buffer, GPU time from timestamps (and per step with --steps), for each way
of writing a block (gpu_sort.COALESCE 0 and 1). Peer: ``torch.sort(keys, stable=True)`` on int64 keys (CUB's
radix sort; it sorts the key and returns the order, the same work as our key/value pairs), CUDA events, keys
CUB sorts all 64 bits; the ``bits`` column says how many ours sorts. Every result is checked against numpy's stable argsort first.

  python benchmarks/sort_bench.py [--sizes depth:6000000,tiles:25000000] [--repeats 20] [--csv out/bench/sort.csv]

Rows: workload, keys, coalesce, ours GPU ms (median), ours / torch, the SM clock before and after (NVML).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from bench_common import append_csv, gpu_clock, hold_gpu_clock  # noqa: E402

from gs_ibl_addon.core.render import gpu_sort  # noqa: E402
from gs_ibl_addon.core.vk import Buffer, Recorder, get_context  # noqa: E402

WORKLOADS = {"depth": 32, "tiles": 15}


def make_keys(kind: str, n: int, rng) -> tuple[np.ndarray, int | None]:
    bits = WORKLOADS[kind]
    if kind == "depth":
        return rng.integers(0, 1 << 32, n, dtype=np.uint64).astype(np.uint32), None
    keys = rng.integers(0, (1 << bits) - 1, n).astype(np.uint32)  # uniform tiles: every digit's run is short
    drop = (1 << bits) - 1
    keys[rng.random(n) < 0.09] = drop
    return keys, drop


def time_ours(ctx, keys: np.ndarray, bits: int, drop: int | None, repeats: int, steps: bool) -> tuple[float, dict]:
    n = len(keys)
    kb, vb, cb = Buffer(ctx, n * 4, "k"), Buffer(ctx, n * 4, "v"), Buffer(ctx, 16, "c")
    sorter = gpu_sort.RadixSorter(ctx, n)
    vals = np.arange(n, dtype=np.uint32)
    order = np.argsort(keys, kind="stable")
    if drop is not None:
        order = order[keys[order] != drop]
    times, parts = [], {}
    for r in range(repeats + 1):
        kb.write(keys)
        vb.write(vals)
        cb.write(np.array([n, 0, 0, 0], np.uint32))
        rec = Recorder(ctx, timestamps=True)
        sorter.record(rec, kb, vb, cb, 0, bits, drop, stamps="sort" if steps else None)
        rec.timestamp("end")
        t = rec.submit()
        if r == 0:  # the first run is checked, not timed
            kept = int(cb.read(np.uint32, 1)[0])
            got = vb.read(np.uint32, n)[:kept]
            if kept != len(order) or not np.array_equal(got, order):
                raise SystemExit(f"our sort of {n} keys ({bits} bits) differs from numpy's stable argsort")
            continue
        times.append(t["total"])
        for k, v in t.items():
            parts.setdefault(k, []).append(v)
    sorter.destroy()
    for b in (kb, vb, cb):
        b.destroy()
    return statistics.median(times), {k: statistics.median(v) for k, v in parts.items() if k != "total"}


def time_torch(keys: np.ndarray, repeats: int) -> float | str:
    try:
        import torch
        if not torch.cuda.is_available():
            return ""
    except Exception:
        return ""
    k = torch.from_numpy(keys.astype(np.int64)).cuda()
    torch.sort(k, stable=True)
    times = []
    for _ in range(repeats):
        a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        a.record()
        torch.sort(k, stable=True)
        b.record()
        torch.cuda.synchronize()
        times.append(a.elapsed_time(b))
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="depth:6000000,tiles:25000000")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--coalesce", default="0,1")
    ap.add_argument("--steps", action="store_true", help="a timestamp after every hist, scan and scatter")
    ap.add_argument("--block", choices=("auto", "long", "short"), default="auto",
                    help="blocks of 4096 keys (long) or 512 (short) whatever the sort's length (auto: the sorter's rule)")
    ap.add_argument("--csv", default="")
    a = ap.parse_args()
    if a.block != "auto":
        gpu_sort.short_blocks = lambda _ctx, _capacity, bits, *_: a.block == "short" and bits == 8
    keep = hold_gpu_clock()  # noqa: F841 (holds the SM clock)
    ctx = get_context()
    rng = np.random.default_rng(24)
    rows = []
    print(f"{ctx.device_name}; sorter digits {gpu_sort.digit_bits_for(ctx)}, subgroup {ctx.subgroup_size}")
    print(f"blocks: {a.block}")
    print("| workload | keys | bits | coalesce | ours GPU ms | torch.sort ms | ours / torch | SM MHz |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for spec in a.sizes.split(","):
        kind, n = spec.split(":")
        keys, drop = make_keys(kind, int(n), rng)
        peer = time_torch(keys, a.repeats)
        for c in (int(x) for x in a.coalesce.split(",")):
            gpu_sort.COALESCE = c
            clock0 = gpu_clock()
            ours, parts = time_ours(ctx, keys, WORKLOADS[kind], drop, a.repeats, a.steps)
            clock = f"{clock0}-{gpu_clock()}"
            ratio = ours / peer if peer else ""
            print(f"| {kind} | {len(keys):,} | {WORKLOADS[kind]} | {c} | {ours:.3f} | "
                  f"{peer if peer == '' else f'{peer:.3f}'} | {ratio if ratio == '' else f'{ratio:.2f}'} | {clock} |")
            if parts:
                print("  steps:", ", ".join(f"{k} {v:.3f}" for k, v in parts.items()))
            rows.append({"date": datetime.date.today().isoformat(), "device": ctx.device_name, "workload": kind,
                         "keys": len(keys), "bits": WORKLOADS[kind], "coalesce": c, "block": a.block, "ours_ms": round(ours, 4),
                         "torch_ms": peer if peer == "" else round(peer, 4), "sm_clock": clock,
                         **{f"step_{k}": round(parts.get(k, 0.0), 4) for k in ("sort.hist", "sort.scan", "sort.scatter")}})
    if a.csv:
        append_csv(a.csv, rows)


if __name__ == "__main__":
    main()
