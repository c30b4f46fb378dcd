"""Per-stage GPU time of the splat renderer over splat counts and cube face sizes (timestamp queries).

Run: python benchmarks/renderer_bench.py [--counts 10000,50000,...] [--faces 64,256,1024] [--repeats 10]
Prints a markdown table and appends rows to out/bench/renderer.csv (device, date, count, face, stage times);
The scene is random_scene (realistic scale/opacity spread) filling a box around the probe, like an environment;
above 50k splats the splats shrink as 1/sqrt(count), as a denser capture of the same surfaces would.
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

from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

STAGES = ["preprocess", "sort_depth", "emit", "sort_tiles", "ranges", "raster", "total"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="10000,50000,100000,1000000")
    ap.add_argument("--faces", default="64,256,1024")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--sh-degree", type=int, default=3)
    ap.add_argument("--extent", type=float, default=5.0, help="half size of the box of splats around the probe")
    ap.add_argument("--max-chunks", type=int, help="override the raster's chunk limit (experiments)")
    ap.add_argument("--target-groups", type=int, help="override the raster's workgroup target (experiments)")
    ap.add_argument("--hold-clock", action="store_true", help="keep a CUDA context open (torch) to hold the SM clock")
    ap.add_argument("--csv", default=os.path.join(os.path.dirname(__file__), "..", "out", "bench", "renderer.csv"),
                    help="CSV to append to (copy it into docs/bench/ to publish a run)")
    args = ap.parse_args()
    holder = hold_gpu_clock() if args.hold_clock else None
    ctx = get_context()
    import gs_ibl_addon.core.render.renderer as renderer_module
    if args.max_chunks:
        renderer_module.MAX_RASTER_CHUNKS = args.max_chunks
    if args.target_groups:
        renderer_module.RASTER_TARGET_GROUPS = args.target_groups
    date = datetime.date.today().isoformat()
    print(f"device: {ctx.device_name}, date {date}, SH degree {args.sh_degree}, median of {args.repeats}, "
          f"clock held by CUDA: {holder is not None}")
    print("| splats | face | instances | " + " | ".join(STAGES) + " | wall ms |")
    print("|---" * (len(STAGES) + 4) + "|")
    rows = []
    for n in [int(x) for x in args.counts.split(",")]:
        t = time.perf_counter()
        scene = bench_scene(n, args.sh_degree, args.extent)
        renderer = SplatRenderer(scene, ctx)
        upload_s = time.perf_counter() - t
        for face in [int(x) for x in args.faces.split(",")]:
            batch = ViewBatch.cubemap([0.0, 0.0, 0.0], face)
            warm_up(lambda: renderer.render(batch, timestamps=True))
            runs = [renderer.render(batch, timestamps=True) for _ in range(args.repeats)]
            med = {s: statistics.median(r.timings_ms.get(s, 0.0) for r in runs) for s in STAGES}
            wall = statistics.median(r.wall_ms for r in runs)
            inst = runs[-1].instances
            print(f"| {n:,} | {face} | {inst:,} | " + " | ".join(f"{med[s]:.3f}" for s in STAGES) + f" | {wall:.1f} |",
                  flush=True)
            rows.append({"device": ctx.device_name, "date": date, "sm_mhz": gpu_clock(), "splats": n, "face": face, "sh_degree": args.sh_degree,
                         "instances": inst, **{f"{s}_ms": round(med[s], 4) for s in STAGES}, "wall_ms": round(wall, 2),
                         "setup_s": round(upload_s, 2)})
        renderer.close()
    append_csv(args.csv, rows)

if __name__ == "__main__":
    main()
