"""Growing the light volume over a mesh that left it, against baking it whole again (issue 37: "re-baked only when ...
a mesh leaves it, and then only the part that changed").

Run:  .venv/bin/python benchmarks/volume_grow_bench.py [--points 256] [--budget 512]
      [--csv docs/bench/volume_grow_lavapipe.csv] [--png docs/img/volume_grow.png]

The sample room with white spheres (r 0.25) at volume_bench's places. The volume is baked as Lighting Volume bakes
it (volume_refine.bake_light_volume: the light's measurement, the grid at its share of the budget, centres and
bricks) over a sphere at the table and one at the room's centre; then that sphere is dragged by each of MOVES and
the volume is (a) grown (volume_refine.extend_volume: new nodes, new cells' centres and their bricks) and (b) baked
whole again, each timed on the same renderer. A growth keeps the first bake's node spacing; the moves are drags of
0.4-1.0 m, what Update When Moved sees. Accuracy: per-point error against dense per-point probes
(volume_bench.reference) at the moved sphere and at the table's, which did not move. Rows: move, method, probes
rendered, bake s, the error mean and 95th percentile, the camera-half cell (auto_light_bench's: within 3% in all
channels). The load average is on every row; times are ratios in the same run."""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)
from volume_bench import boxes_of, centre, errors, reference, sphere_points  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe import volume as vol  # noqa: E402
from gs_ibl_addon.core.probe.volume_refine import bake_light_volume, extend_volume  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402

MOVES = {"+0.4 m x": (0.4, 0.0, 0.0), "+0.8 m x": (0.8, 0.0, 0.0), "+0.6 m y": (0.0, 0.6, 0.0),
         "-1.0 m y": (0.0, -1.0, 0.0)}  # the centre's sphere, dragged
START, STILL = "centre", "table"


def moved_points(offset, points: int):
    """sphere_points of the centre's sphere moved by ``offset`` (seen from the centre place's camera)."""
    pts, nrm, facing = sphere_points(START, points)
    return pts + np.asarray(offset, np.float64), nrm, facing


def run(points: int, budget: int) -> list[dict]:
    scene = read_scene(os.path.join(os.path.dirname(HERE), "samples", "room.ply"))
    rows = []
    with SplatRenderer(scene) as r:
        device = r.ctx.device_name
        data = {STILL: sphere_points(STILL, points)}
        data.update({m: moved_points(o, points) for m, o in MOVES.items()})
        refs = {p: reference(r, *data[p][:2]) for p in data}
        t0 = time.perf_counter()
        _plan, first = bake_light_volume(r, boxes_of([STILL, START]), budget)
        t_first = time.perf_counter() - t0
        print(f"{device}: first bake over {STILL} and {START}: {first.timings['probes']} probes, {t_first:.1f} s",
              flush=True)
        for dest, offset in MOVES.items():
            boxes = boxes_of([STILL, centre(START) + np.asarray(offset)])
            t0 = time.perf_counter()
            grown = extend_volume(r, first, boxes, budget)
            t_grow = time.perf_counter() - t0
            t0 = time.perf_counter()
            _plan, whole = bake_light_volume(r, boxes, budget)
            t_whole = time.perf_counter() - t0
            for method, v, secs in (("grown", grown, t_grow), ("whole", whole, t_whole)):
                if v is None:
                    print(f"{dest}: {method}: over the budget, baked whole instead", flush=True)
                    continue
                for where in (dest, STILL):
                    pts, nrm, facing = data[where]
                    row = {"date": datetime.date.today().isoformat(), "device": device,
                           "load": round(os.getloadavg()[0], 2), "move": dest, "method": method,
                           "probes": v.timings["probes"], "grid": v.spec.count, "bake_s": round(secs, 4),
                           "sphere": "moved" if where == dest else "still",
                           **errors(vol.sample(v, pts, nrm), refs[where], facing)}
                    rows.append(row)
                    print(f"{row['move']:18} {method:5} {row['sphere']:5} probes {row['probes']:4} "
                          f"{secs:8.3f} s  err {100 * row['err_mean']:.2f}% (p95 {100 * row['err_p95']:.2f}%) "
                          f"cell {row['cell_r']:.3f}/{row['cell_g']:.3f}/{row['cell_b']:.3f}", flush=True)
    return rows


def plot(rows: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    moves = list(dict.fromkeys(r["move"] for r in rows))
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    x = np.arange(len(moves))
    for i, method in enumerate(("grown", "whole")):
        t = [next((r["bake_s"] for r in rows if r["move"] == m and r["method"] == method), np.nan) for m in moves]
        e = [next((100 * r["err_mean"] for r in rows if r["move"] == m and r["method"] == method
                   and r["sphere"] == "moved"), np.nan) for m in moves]
        a.bar(x + (i - 0.5) * 0.35, t, 0.35, label=method)
        b.bar(x + (i - 0.5) * 0.35, e, 0.35, label=method)
    for ax, label in ((a, "bake, s"), (b, "moved sphere: per-point error, %")):
        ax.set_xticks(x, moves, fontsize=8)
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    fig.suptitle(f"Light volume grown over a moved sphere against baked whole ({rows[0]['device']}, "
                 f"{rows[0]['date']})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=256, help="shading points per sphere")
    ap.add_argument("--budget", type=int, default=512, help="Volume Probes")
    ap.add_argument("--csv", default="docs/bench/volume_grow_lavapipe.csv")
    ap.add_argument("--png", default="docs/img/volume_grow.png")
    args = ap.parse_args()
    rows = run(args.points, args.budget)
    with open(args.csv, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {args.csv}")
    if args.png:
        plot(rows, args.png)


if __name__ == "__main__":
    main()
