"""Many probes in one batch (SplatRenderer.render_probes + gpu_filters.filter_probes) against the same probes one
at a time: GPU and wall time per batch and per probe, with and without a level of detail.

Run: python benchmarks/multi_probe_bench.py [--counts 1000000] [--probes 1,8,27,125] [--faces 32] [--ks 0,1,2]
     [--repeats 10] [--hold-clock] [--csv out/bench/multi_probe.csv] [--quick]

Probes sit on a regular grid inside bench_scene's box (N = 1: its centre; 8, 27, 125: 2^3, 3^3, 5^3 grids over
[-3, 3]^3, inside the [-5, 5]^3 cloud); a probe is its render at ``face``^2 + the exact irradiance (16^2, read
back). Per splat count, N, face size and k (0: every splat; k > 0: the level of detail, each probe its own cut):
  batch     one render_probes submission + one filter_probes submission; GPU ms (timestamps: render + filter),
            wall ms (host, to the irradiance read back), the render's stages, groups (submission split to fit)
  single    the same N probes one after another (render + filter_probe each, as a bake does), summed
  per_probe the batch's GPU / wall ms divided by N, and the speed-up over single (GPU and wall)
  err_pct   the largest relative RMS irradiance difference of a batched probe from its single bake (float
            rounding: the two differ only in the raster's chunking), and for k > 0 lod_err_pct, the largest
            error of the level of detail against full detail (the k = 0 batch)
Medians over --repeats. With --hold-clock a CUDA context (torch) keeps an NVIDIA GPU's SM clock up
(shared/NOTES-vulkan-and-gpu.md); the SM clock (NVML) is recorded per row ('' where NVML is missing).
The target (issue 15 part 5): 125 probes of 1M splats at 32^2 in < 50 ms GPU.
--quick: 20k splats, N up to 27, 2 repeats (a minute or two on a 2-core lavapipe machine).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_common import append_csv, bench_scene, gpu_clock, hold_gpu_clock, warm_up  # noqa: E402

import numpy as np  # noqa: E402

from gs_ibl_addon.core.bake import relative_rms  # noqa: E402
from gs_ibl_addon.core.probe import filter_probe  # noqa: E402
from gs_ibl_addon.core.probe.gpu_filters import filter_probes  # noqa: E402
from gs_ibl_addon.core.render.lod import build_lod  # noqa: E402
from gs_ibl_addon.core.render.renderer import PAIR_BYTES, PAIR_BYTES_LOD, SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
STAGES = ("preprocess", "lod_compact", "sort_depth", "emit", "sort_tiles", "ranges", "raster")
IRRADIANCE_SIZE = 16


def grid_positions(n: int, half: float = 3.0) -> np.ndarray:
    """n = m^3 probes on a regular m x m x m grid over [-half, half]^3 (n = 1: the centre)."""
    m = round(n ** (1 / 3))
    if m ** 3 != n:
        raise SystemExit(f"--probes: {n} is not a cube (1, 8, 27, 64, 125, ...)")
    axis = np.linspace(-half, half, m) if m > 1 else np.zeros(1)
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)


def batch_probe(r: SplatRenderer, pos: np.ndarray, face: int, k: float) -> tuple[float, dict, np.ndarray]:
    """(GPU ms of render + filter, render stages, irradiance (N, 6, m, m, 3)) of one batch."""
    res = r.render_probes(pos, face, lod_k=k, timestamps=True, wait=False)
    f = filter_probes(res.frame, IRRADIANCE_SIZE, "exact")
    t = res.timings_ms
    filt = f.timings_ms.get("total", 0.0)
    return t.get("total", 0.0) + filt, dict(t, filter=filt), f.irradiance


def single_probes(r: SplatRenderer, pos: np.ndarray, face: int, k: float) -> tuple[float, np.ndarray]:
    """(GPU ms summed over the probes, irradiance (N, 6, m, m, 3)) of the probes one at a time."""
    gpu, irr = 0.0, []
    for o in pos:
        res = r.render(ViewBatch.cubemap(o, face), timestamps=True, wait=False, lod_k=k)
        p = filter_probe(res.frame, IRRADIANCE_SIZE, method="exact", roughness=None, read_radiance=False)
        gpu += res.timings_ms.get("total", 0.0) + p.timings_ms.get("filter_gpu", 0.0)
        irr.append(p.irradiance)
    return gpu, np.stack(irr)


def median_run(step, repeats: int) -> tuple[float, float, object]:
    """(median GPU ms, median wall ms, the last run's other results) of ``step() -> (gpu_ms, *rest)``."""
    walls, gpus, rest = [], [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = step()
        walls.append((time.perf_counter() - t0) * 1e3)
        gpus.append(out[0])
        rest = out[1:]
    return statistics.median(gpus), statistics.median(walls), rest


def print_table(rows: list[dict]) -> None:
    cols = ("splats", "face", "k", "probes", "groups", "sm_mhz", "batch_gpu_ms", "batch_wall_ms", "per_probe_gpu_ms",
            "single_per_probe_gpu_ms", "speedup_gpu", "per_probe_wall_ms", "single_per_probe_wall_ms", "speedup_wall",
            "err_pct", "lod_err_pct")
    w = [max(len(c), *(len(str(r.get(c, ""))) for r in rows)) for c in cols]
    print("\n" + "  ".join(c.rjust(x) for c, x in zip(cols, w)))
    for r in rows:
        print("  ".join(str(r.get(c, "")).rjust(x) for c, x in zip(cols, w)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="1000000")
    ap.add_argument("--probes", default="1,8,27,125")
    ap.add_argument("--faces", default="32")
    ap.add_argument("--ks", default="0,1,2", help="0: full detail; > 0: level of detail with that lod_k")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--hold-clock", action="store_true")
    ap.add_argument("--skip-single", action="store_true", help="batches only (no one-at-a-time comparison)")
    ap.add_argument("--csv", default=os.path.join(ROOT, "out", "bench", "multi_probe.csv"))
    ap.add_argument("--quick", action="store_true", help="20k splats, N up to 27, 2 repeats (lavapipe smoke run)")
    args = ap.parse_args()
    if args.quick:
        args.counts, args.probes, args.repeats = "20000", "1,8,27", 2
    holder = hold_gpu_clock() if args.hold_clock else None
    ctx = get_context()
    date = datetime.date.today().isoformat()
    ks = [float(x) for x in args.ks.split(",")]
    faces = [int(x) for x in args.faces.split(",")]
    probe_counts = [int(x) for x in args.probes.split(",")]
    rows: list[dict] = []
    print(f"device: {ctx.device_name}; clock held by CUDA: {holder is not None}", flush=True)
    if os.path.exists(args.csv):
        os.remove(args.csv)  # one run per CSV
    for n in [int(x) for x in args.counts.split(",")]:
        scene = bench_scene(n)
        tree = build_lod(scene) if any(ks) else None
        # Batches and single probes on separate renderers: a renderer keeps the pair and instance buffers of its
        # largest batch, and single probes dispatched over that capacity would be charged for the batch's size.
        renderers = {0.0: SplatRenderer(scene, ctx)}
        if not args.skip_single:
            renderers["single"] = SplatRenderer(scene, ctx)
        if tree is not None:
            renderers["lod"] = SplatRenderer(scene, ctx, lod=tree)
            if not args.skip_single:
                renderers["single_lod"] = SplatRenderer(scene, ctx, lod=tree)
            print(f"{n:,} splats: level of detail built in {tree.build_s:.1f} s, {tree.count:,} nodes", flush=True)
        del scene
        try:
            for face in faces:
                for probes in probe_counts:
                    pos = grid_positions(probes)
                    full_irr = None
                    for k in ks:
                        r = renderers["lod" if k else 0.0]
                        warm_up(lambda: batch_probe(r, pos, face, k), 0.3)
                        gpu, wall, (stages, irr) = median_run(lambda: batch_probe(r, pos, face, k), args.repeats)
                        groups = -(-probes // max(1, r.slots)) if probes > 1 else 1
                        row = {"device": ctx.device_name, "date": date, "sm_mhz": gpu_clock(), "splats": n,
                               "nodes": r.lod.count if r.lod is not None else n, "face": face, "k": k,
                               "probes": probes, "groups": groups,
                               "pair_mib": round(r.nodes * r.slots * (PAIR_BYTES_LOD if r.lod else PAIR_BYTES) / 2**20, 1),
                               "instances": "", "drawn_per_group": r.drawn,
                               "batch_gpu_ms": round(gpu, 3), "batch_wall_ms": round(wall, 3),
                               "per_probe_gpu_ms": round(gpu / probes, 4), "per_probe_wall_ms": round(wall / probes, 4),
                               **{f"{s}_ms": round(stages.get(s, 0.0), 3) for s in STAGES + ("filter",)},
                               **dict.fromkeys(("single_gpu_ms", "single_wall_ms", "single_per_probe_gpu_ms",
                                                "single_per_probe_wall_ms", "speedup_gpu", "speedup_wall", "err_pct",
                                                "lod_err_pct"), "")}  # every row has every column (one CSV header)
                        res = r.render_probes(pos, face, lod_k=k)
                        row["instances"] = res.instances
                        if k == 0:
                            full_irr = irr
                        elif full_irr is not None:
                            row["lod_err_pct"] = round(100 * max(relative_rms(a, b) for a, b in zip(irr, full_irr)), 4)
                        if not args.skip_single:
                            rs = renderers["single_lod" if k else "single"]
                            warm_up(lambda: single_probes(rs, pos[:1], face, k), 0.3)
                            sg, sw, (sirr,) = median_run(lambda: single_probes(rs, pos, face, k),
                                                         max(1, args.repeats // 3))
                            row.update({"single_gpu_ms": round(sg, 3), "single_wall_ms": round(sw, 3),
                                        "single_per_probe_gpu_ms": round(sg / probes, 4),
                                        "single_per_probe_wall_ms": round(sw / probes, 4),
                                        "speedup_gpu": round(sg / max(gpu, 1e-9), 2),
                                        "speedup_wall": round(sw / max(wall, 1e-9), 2),
                                        "err_pct": round(100 * max(relative_rms(a, b) for a, b in zip(irr, sirr)), 5)})
                        rows.append(row)
                        print(" ".join(f"{a}={b}" for a, b in row.items() if a not in ("device", "date")), flush=True)
                        append_csv(args.csv, [row])
        finally:
            for r in renderers.values():
                r.close()
    print_table(rows)
    print(f"\nCSV: {os.path.relpath(args.csv)}")


if __name__ == "__main__":
    main()
