"""A full probe's wall time against its GPU time: render a cubemap -> exact irradiance (16^2) -> read back what a
bake writes, per splat count and face size.

Run: python benchmarks/probe_bench.py [--counts 10000,100000,1000000] [--faces 32,64,128,256,512,1024]
     [--repeats 20] [--hold-clock] [--csv docs/bench/probe_wall.csv] [--png docs/probe-wall.png]

Per probe, medians over the repeats:
  gpu      render + filter GPU time (timestamp queries)
  wall     host wall time of render(batch) + filter_probe(frame) with the irradiance read back (the frame stays on
           the GPU: a face-size search step)
  wall_rad the same plus the radiance read back (what the bake writes once, for the face size it keeps)
  wall_old the path before the GPU frame: radiance read back, then uploaded again to filter (for comparison)
Targets (issue 15): wall <= gpu + 1 ms up to 256^2 faces, wall <= 1.5 x gpu above.
With --hold-clock a CUDA context (torch) is kept open in this process so an NVIDIA GPU holds its SM clock
(shared/NOTES-vulkan-and-gpu.md: a Vulkan-only process falls to 345 MHz); the SM clock (NVML) is recorded per row.
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

from gs_ibl_addon.core.probe import filter_probe  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def probe(r: SplatRenderer, batch: ViewBatch, read_radiance: bool) -> float:
    """GPU ms of one probe (render + filter); the wall time is the caller's."""
    res = r.render(batch, timestamps=True, wait=False)  # the filter queues behind the render: one host wait
    pr = filter_probe(res.frame, 16, method="exact", roughness=None, read_radiance=read_radiance)
    return res.timings_ms.get("total", 0.0) + pr.timings_ms.get("filter_gpu", 0.0)


def probe_old(r: SplatRenderer, batch: ViewBatch) -> None:
    """The host round trip the GPU frame replaced: read the radiance back, upload it again to filter."""
    res = r.render(batch, timestamps=True)
    filter_probe(np.stack(res.images), 16, method="exact", roughness=None, use_gpu=True, vk_context=r.ctx)


def timed(fn, repeats: int) -> tuple[float, float]:
    walls, gpus = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        g = fn()
        walls.append((time.perf_counter() - t0) * 1e3)
        gpus.append(g or 0.0)
    return statistics.median(walls), statistics.median(gpus)


def plot(rows: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    counts = sorted({r["splats"] for r in rows})
    fig, axes = plt.subplots(1, len(counts), figsize=(4.2 * len(counts), 3.6), squeeze=False)
    for ax, n in zip(axes[0], counts):
        sub = sorted((r for r in rows if r["splats"] == n), key=lambda r: r["face"])
        faces = [r["face"] for r in sub]
        for key, label, style in (("gpu_ms", "GPU", "k-o"), ("wall_ms", "wall (irradiance read back)", "C0-s"),
                                  ("wall_rad_ms", "wall + radiance read back", "C1-^"),
                                  ("wall_old_ms", "wall, old host round trip", "C3--x")):
            ax.plot(faces, [r[key] for r in sub], style, label=label, ms=4)
        ax.plot(faces, [1.5 * r["gpu_ms"] if r["face"] > 256 else r["gpu_ms"] + 1 for r in sub], ":", color="grey",
                label="target (GPU + 1 ms; 1.5x GPU above 256²)")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("cube face size (px)")
        ax.set_title(f"{n:,} splats")
        ax.grid(alpha=0.3, which="both")
    axes[0][0].set_ylabel("ms per probe")
    axes[0][0].legend(fontsize=7)
    r0 = rows[0]
    fig.suptitle(f"Full probe (render + exact irradiance 16²): {r0['device']}, SM {r0['sm_mhz']} MHz, {r0['date']}",
                 fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="10000,100000,1000000")
    ap.add_argument("--faces", default="32,64,128,256,512,1024")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--hold-clock", action="store_true", help="keep a CUDA context open (torch) to hold the SM clock")
    ap.add_argument("--no-old", action="store_true", help="skip the old host round-trip path")
    ap.add_argument("--csv", default=os.path.join(HERE, "..", "out", "bench", "probe_wall.csv"),
                    help="CSV to append to (docs/bench/probe_wall.csv holds the published runs)")
    ap.add_argument("--png", default="", help="plot to write (e.g. docs/probe-wall.png)")
    ap.add_argument("--plot-csv", default="", help="only plot this CSV (a published run) into --png")
    args = ap.parse_args()
    if args.plot_csv:
        import csv
        with open(args.plot_csv) as f:
            rows = [{k: (v if k in ("device", "date", "sm_mhz") else float(v) if "." in v or "nan" in v else
                         int(v) if v.isdigit() else v) for k, v in r.items()} for r in csv.DictReader(f)]
        plot(rows, args.png)
        return
    holder = hold_gpu_clock() if args.hold_clock else None
    ctx = get_context()
    rows = []
    date = datetime.date.today().isoformat()
    print(f"device: {ctx.device_name}; clock held by CUDA: {holder is not None}")
    print("| splats | face | SM MHz | GPU ms | wall ms | wall - GPU | wall / GPU | + radiance ms | old path ms | target |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in [int(x) for x in args.counts.split(",")]:
        with SplatRenderer(bench_scene(n), ctx) as r:
            for face in [int(x) for x in args.faces.split(",")]:
                batch = ViewBatch.cubemap([0.0, 0.0, 0.0], face)
                warm_up(lambda: probe(r, batch, False), 0.5)
                wall, gpu = timed(lambda: probe(r, batch, False), args.repeats)
                wall_rad, _ = timed(lambda: probe(r, batch, True), max(3, args.repeats // 2))
                wall_old = float("nan") if args.no_old else timed(lambda: probe_old(r, batch), max(3, args.repeats // 4))[0]
                mhz = gpu_clock()
                ok = wall <= gpu + 1.0 if face <= 256 else wall <= 1.5 * gpu
                print(f"| {n:,} | {face} | {mhz} | {gpu:.3f} | {wall:.3f} | {wall - gpu:.3f} | {wall / max(gpu, 1e-9):.2f} "
                      f"| {wall_rad:.2f} | {wall_old:.2f} | {'met' if ok else 'missed'} |", flush=True)
                rows.append({"device": ctx.device_name, "date": date, "sm_mhz": mhz, "clock_held": holder is not None,
                             "splats": n, "face": face, "gpu_ms": round(gpu, 4), "wall_ms": round(wall, 4),
                             "wall_rad_ms": round(wall_rad, 4), "wall_old_ms": round(wall_old, 4),
                             "target_met": ok})
    append_csv(args.csv, rows)
    if args.png:
        plot(rows, args.png)


if __name__ == "__main__":
    main()
