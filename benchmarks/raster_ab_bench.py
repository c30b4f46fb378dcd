"""Our renderer against itself with the raster's or emit's switches set otherwise (peer_bench.VARIANTS), same scenes
and cube faces, interleaved in one process: for a device gsplat cannot run on (lavapipe), where the peer of a kernel
change is the kernels before it. The first variant is the baseline; every row gives its ratio to it.

  python benchmarks/raster_ab_bench.py [--variants plain,strips,strips-noconic] [--scenes shell,random]
         [--counts 1000000] [--faces 32,64,128,256,512] [--rounds 3] [--csv out/bench/raster_ab.csv]
         [--png out/bench/raster_ab.png]

Each variant is a renderer of its own (a switch is read when a batch shape's program is first recorded). Per scene
x count x face: one warm-up render each, then ``rounds`` rounds of one render of each variant in turn; medians of
the raster's and the whole frame's GPU time (timestamps) and of the wall time of render(). The images of every
variant are compared with the baseline's (max |difference|: 0 for strips against plain, which skip only pairs
every pixel of a strip rejects; "strips-noconic" at 64²-256² also swaps the conic kernel's ray test for the plain
kernel's plane forms, so its row differs by their rounding, up to a flipped edge pixel, and its ratio is of both
changes).
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

from bench_common import append_csv  # noqa: E402
from peer_bench import SCENES, STAGES, VARIANTS, Ours, log  # noqa: E402


def run(args) -> list[dict]:
    from gs_ibl_addon.core.vk import get_context
    ctx = get_context()
    date = datetime.date.today().isoformat()
    load = os.getloadavg()[0]
    log(f"device {ctx.device_name}, load {load:.1f}, variants {args.variants}")
    names = args.variants.split(",")
    rows = []
    for kind in args.scenes.split(","):
        for n in [int(x) for x in args.counts.split(",")]:
            scene = SCENES[kind](n)
            rends = [Ours(scene, ctx, v) for v in names]
            for face in [int(x) for x in args.faces.split(",")]:
                for r in rends:
                    r.set_face(face)
                    r.rep()  # warm-up: pipelines, budgets, loop-limit chunks
                reps = {v: [] for v in names}
                for _ in range(args.rounds):
                    for v, r in zip(names, rends):
                        reps[v].append(r.rep())
                base_img = rends[0].images()
                base = None
                for v, r in zip(names, rends):
                    med = {k: statistics.median(x[k] for x in reps[v]) for k in ("gpu_ms", "wall_ms", *STAGES)}
                    diff = float(np.abs(r.images() - base_img).max()) if r is not rends[0] else 0.0
                    base = base or med
                    row = {"device": ctx.device_name, "date": date, "load": round(load, 1), "scene": kind,
                           "splats": n, "face": face, "variant": v, "renderer": VARIANTS[v][0],
                           **{f"{st}_ms": round(med[st], 2) for st in STAGES},
                           "gpu_ms": round(med["gpu_ms"], 2), "wall_ms": round(med["wall_ms"], 2),
                           "raster_ratio": round(med["raster"] / base["raster"], 3),
                           "gpu_ratio": round(med["gpu_ms"] / base["gpu_ms"], 3), "max_image_diff": diff,
                           "pairs": reps[v][-1]["pairs"], "rounds": args.rounds}
                    rows.append(row)
                    log(f"{kind} {n:>9,} {face:>5} {v:>15}: raster {row['raster_ms']:9.1f} ms "
                        f"({row['raster_ratio']:.2f}x) emit {row['emit_ms']:8.1f} frame {row['gpu_ms']:9.1f} ({row['gpu_ratio']:.2f}x) wall "
                        f"{row['wall_ms']:9.1f} | diff {diff:.1e}")
                append_csv(args.csv, rows[-len(names):])
            for r in rends:
                r.close()
    return rows


def plot(rows: list[dict], png: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    groups = sorted({(r["scene"], r["splats"]) for r in rows})
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    fig, axes = plt.subplots(1, len(groups), figsize=(5 * len(groups), 3.8), squeeze=False)
    for ax, (scene, n) in zip(axes[0], groups):
        sel = [r for r in rows if r["scene"] == scene and r["splats"] == n]
        faces = sorted({r["face"] for r in sel})
        x = np.arange(len(faces))
        w = 0.8 / len(variants)
        for i, v in enumerate(variants):
            y = [next((r["raster_ratio"] for r in sel if r["face"] == f and r["variant"] == v), np.nan) for f in faces]
            ax.bar(x + (i - (len(variants) - 1) / 2) * w, y, w, label=VARIANTS[v][0])
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xticks(x, [f"{f}²" for f in faces])
        ax.set_title(f"{scene}, {n:,} splats")
        ax.set_xlabel("cube face")
        ax.set_ylabel(f"raster time / {VARIANTS[variants[0]][0]}")
        ax.legend(fontsize=8)
    r0 = rows[0]
    fig.suptitle(f"Raster kernels A/B, one process: {r0['device']}, {r0['date']}, load {r0['load']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    log(f"wrote {png}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variants", default="plain,strips,strips-noconic", help="peer_bench.VARIANTS, baseline first")
    ap.add_argument("--scenes", default="shell,random")
    ap.add_argument("--counts", default="1000000")
    ap.add_argument("--faces", default="32,64,128,256,512")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--csv", default=os.path.join(HERE, "..", "out", "bench", "raster_ab.csv"))
    ap.add_argument("--png", default=os.path.join(HERE, "..", "out", "bench", "raster_ab.png"))
    args = ap.parse_args()
    plot(run(args), args.png)


if __name__ == "__main__":
    main()
