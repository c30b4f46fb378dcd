"""A whole probe on the GPU (cubemap render + exact irradiance filter) against splat count and face size.

Run: python benchmarks/probe_bench.py [--counts 50000,1000000,6000000] [--faces 32,64,128,256,512] [--repeats 10]
GPU time from timestamp queries (median), render and filter separately; appends to out/bench/probe.csv.
The scene is benchmarks/renderer_bench.py's (random splats around the probe, shrinking with the count).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_common import append_csv, bench_scene, warm_up  # noqa: E402

import numpy as np  # noqa: E402

from gs_ibl_addon.core.probe import filter_probe  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="50000,1000000,6000000")
    ap.add_argument("--faces", default="32,64,128,256,512")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--csv", default=os.path.join(os.path.dirname(__file__), "..", "out", "bench", "probe.csv"),
                    help="CSV to append to (copy it into docs/bench/ to publish a run)")
    args = ap.parse_args()
    rows = []
    date = datetime.date.today().isoformat()
    print("| splats | face | render ms | filter ms (exact, 16²) | probe ms |")
    print("|---|---|---|---|---|")
    for n in [int(x) for x in args.counts.split(",")]:
        scene = bench_scene(n)
        r = SplatRenderer(scene)
        for face in [int(x) for x in args.faces.split(",")]:
            batch = ViewBatch.cubemap([0.0, 0.0, 0.0], face)
            warm_up(lambda: filter_probe(np.stack(r.render(batch).images), 16, method="exact", roughness=None,
                                         use_gpu=True, vk_context=r.ctx))
            rend, filt = [], []
            for _ in range(args.repeats):
                res = r.render(batch, timestamps=True)
                pr = filter_probe(np.stack(res.images), 16, method="exact", roughness=None, use_gpu=True,
                                  vk_context=r.ctx)
                rend.append(res.timings_ms["total"])
                filt.append(pr.timings_ms["irradiance"])
            mr, mf = statistics.median(rend), statistics.median(filt)
            print(f"| {n:,} | {face} | {mr:.3f} | {mf:.3f} | {mr + mf:.3f} |", flush=True)
            rows.append({"device": r.ctx.device_name, "date": date, "splats": n, "face": face,
                         "render_ms": round(mr, 4), "filter_ms": round(mf, 4), "probe_ms": round(mr + mf, 4)})
        r.close()
    append_csv(args.csv, rows)

if __name__ == "__main__":
    main()
