"""Our renderer against itself with the raster's or emit's switches set otherwise (peer_bench.VARIANTS), same scenes
and cube faces, interleaved in one process: for a device gsplat cannot run on (lavapipe), where the peer of a kernel
change is the kernels before it. The first variant is the baseline; every row gives its ratio to it.

  python benchmarks/raster_ab_bench.py [--variants plain,strips,strips-noconic] [--scenes shell,random]
         [--counts 1000000] [--faces 32,64,128,256,512] [--rounds 3] [--csv out/bench/raster_ab.csv]
         [--png out/bench/raster_ab.png] [--table out/bench/kernel_table.json]
  python benchmarks/raster_ab_bench.py table CSV [CSV ...] [--out gs_ibl_addon/core/render/kernel_table.json]
         [--merge gs_ibl_addon/core/render/kernel_table.json] [--tolerance 0.02]

The kernel table (render/kernel_table.json, read by the renderer): ``table`` reads the rows of A/B variants that
time one kernel choice against the other (peer_bench.TABLE_VARIANTS: plain / strips, emit-slot / emit-splat) from
CSVs of this bench or of peer_bench.py (cube faces and camera frames alike: a frame's size is its larger side),
applies render/kernel_table.py's rule per device class, stage and size, and writes the table; ``--merge`` keeps
the rows of an existing table for the device classes the CSVs do not measure. ``--table`` does the same right
after a bench run, from its own rows. The committed table is
  python benchmarks/raster_ab_bench.py table docs/bench/raster_ab_lavapipe.csv docs/bench/emit_ab_lavapipe.csv \
         docs/bench/peer_nvidia-h200_2026-12-05.csv docs/bench/camera_nvidia-h200_2026-12-05.csv

All variants draw with one renderer (a switch is part of the key of the programs it records, so each variant
records and keeps its own; the scene is uploaded once). Per scene
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
from peer_bench import SCENES, STAGES, TABLE_VARIANTS, VARIANTS, Ours, log  # noqa: E402

TABLE = os.path.join(HERE, "..", "gs_ibl_addon", "core", "render", "kernel_table.json")


def run(args) -> list[dict]:
    from gs_ibl_addon.core.render import kernel_table
    from gs_ibl_addon.core.vk import get_context
    ctx = get_context()
    dev_class = kernel_table.context_class(ctx)
    date = datetime.date.today().isoformat()
    load = os.getloadavg()[0]
    log(f"device {ctx.device_name}, load {load:.1f}, variants {args.variants}")
    names = args.variants.split(",")
    rows = []
    for kind in args.scenes.split(","):
        for n in [int(x) for x in args.counts.split(",")]:
            scene = SCENES[kind](n)
            rends = [Ours(scene, ctx, names[0])]
            rends += [Ours(scene, ctx, v, share=rends[0]) for v in names[1:]]
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
                    kern = r.kernels()
                    row = {"device": ctx.device_name, "device_class": dev_class, "date": date,
                           "load": round(load, 1), "scene": kind, "splats": n, "face": face, "variant": v,
                           "renderer": VARIANTS[v][0], "raster_kernel": kern["raster"], "emit_kernel": kern["emit"],
                           **{f"{st}_ms": round(med[st], 2) for st in STAGES},
                           "gpu_ms": round(med["gpu_ms"], 2), "wall_ms": round(med["wall_ms"], 2),
                           "raster_ratio": round(med["raster"] / base["raster"], 3),
                           "gpu_ratio": round(med["gpu_ms"] / base["gpu_ms"], 3), "max_image_diff": diff,
                           "pairs": reps[v][-1]["pairs"], "rounds": args.rounds}
                    rows.append(row)
                    log(f"{kind} {n:>9,} {face:>5} {v:>15}: raster {row['raster_ms']:9.1f} ms "
                        f"({row['raster_ratio']:.2f}x) emit {row['emit_ms']:8.1f} frame {row['gpu_ms']:9.1f} "
                        f"({row['gpu_ratio']:.2f}x) wall "
                        f"{row['wall_ms']:9.1f} | diff {diff:.1e}")
                append_csv(args.csv, rows[-len(names):])
            for r in rends[::-1]:
                r.close()
    return rows


def table_cells(paths: list[str]) -> tuple[list, dict[str, list[str]]]:
    """kernel_table.Cell of every A/B row (TABLE_VARIANTS) in the CSVs at ``paths``, and per device class the
    sources (file: device, dates)."""
    import csv
    from gs_ibl_addon.core.render import kernel_table
    labels = {VARIANTS[v][0]: v for v in TABLE_VARIANTS}  # older peer_bench CSVs name the variant by its label
    cells, sources = [], {}
    for path in paths:
        if not os.path.exists(path):
            log(f"{path}: no such file, left out")
            continue
        seen: dict[str, set] = {}
        with open(path) as f:
            for row in csv.DictReader(f):
                v = row.get("variant") or labels.get(row.get("renderer", ""), "")
                if v not in TABLE_VARIANTS:
                    continue
                cls = row.get("device_class") or kernel_table.device_class(name=row["device"])
                stage, kernel = TABLE_VARIANTS[v]
                face = int(row.get("face") or max(int(row["width"]), int(row["height"])))
                cells.append(kernel_table.Cell(cls, stage, row.get("view", "cube") + ":" + row["scene"],
                                               int(row["splats"]), face, kernel, float(row["gpu_ms"])))
                seen.setdefault(cls, set()).add(f"{row['device']} {row.get('date', '')}".strip())
        for cls, what in seen.items():
            sources.setdefault(cls, []).append(f"{os.path.relpath(path, os.path.join(HERE, '..'))}: "
                                               + ", ".join(sorted(what)))
    return cells, sources


def write_table(paths: list[str], out: str, merge: str | None = None, tolerance: float | None = None) -> list[dict]:
    """The kernel table from the A/B rows of ``paths`` (module docstring), written to ``out``; ``merge``: a table
    whose rows and sources for other device classes are kept."""
    import json
    from gs_ibl_addon.core.render import kernel_table
    tol = kernel_table.TOLERANCE if tolerance is None else tolerance
    cells, sources = table_cells(paths)
    rows = kernel_table.choose_rows(cells, tol)
    fallback = None
    if merge and os.path.exists(merge):
        with open(merge) as f:
            old = json.load(f)
        kernel_table.KernelTable(old, merge)  # a damaged table is refused, not merged
        measured = {c.device for c in cells}
        rows = [r for r in old["rows"] if r["device"] not in measured] + rows
        rows.sort(key=lambda r: (r["device"], r["stage"], r["face_min"]))
        sources = {**{k: v for k, v in old.get("sources", {}).items() if k not in measured}, **sources}
        fallback = old.get("fallback")
    text = kernel_table.table_json(rows, dict(sorted(sources.items())), tol, fallback)
    kernel_table.KernelTable(json.loads(text), out)  # what the renderer will read must parse
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w") as f:
        f.write(text)
    for r in rows:
        top = "up" if r["face_max"] is None else r["face_max"]
        why = "; ".join(f"{f}: worst loss " + ", ".join(f"{k} {x:+.0%}" for k, x in d["worst_loss"].items())
                        for f, d in r.get("measured", {}).items())
        log(f"{r['device']:>8} {r['stage']:>6} {r['face_min']:>5}-{top:<5} {r['kernel']:<7} ({why})")
    log(f"wrote {out}")
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
    if sys.argv[1:2] == ["table"]:
        tp = argparse.ArgumentParser(prog="raster_ab_bench.py table", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
        tp.add_argument("csvs", nargs="+", help="CSVs of this bench or of peer_bench.py with A/B rows")
        tp.add_argument("--out", default=TABLE)
        tp.add_argument("--merge", help="keep this table's rows for the device classes the CSVs do not measure")
        tp.add_argument("--tolerance", type=float, help="worst losses closer than this are a tie "
                        "(default kernel_table.TOLERANCE)")
        targs = tp.parse_args(sys.argv[2:])
        write_table(targs.csvs, targs.out, targs.merge, targs.tolerance)
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variants", default="plain,strips,strips-noconic", help="peer_bench.VARIANTS, baseline first")
    ap.add_argument("--scenes", default="shell,random")
    ap.add_argument("--counts", default="1000000")
    ap.add_argument("--faces", default="32,64,128,256,512")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--csv", default=os.path.join(HERE, "..", "out", "bench", "raster_ab.csv"))
    ap.add_argument("--png", default=os.path.join(HERE, "..", "out", "bench", "raster_ab.png"))
    ap.add_argument("--table", help="then write the kernel table from this run's A/B rows here (the committed "
                    "table's rows for other device classes kept)")
    args = ap.parse_args()
    plot(run(args), args.png)
    if args.table:
        write_table([args.csv], args.table, merge=TABLE)


if __name__ == "__main__":
    main()
