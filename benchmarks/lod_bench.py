"""The level of detail (render/lod.py): a full probe's GPU and wall time with and without it, and the irradiance
error it costs against full detail.

Run: python benchmarks/lod_bench.py [--counts 100000,1000000,6000000] [--faces 32,64,128,256] [--ks 0.25,0.5,1,2]
     [--repeats 20] [--hold-clock] [--csv docs/bench/lod_<device>.csv] [--png docs/lod.png] [--skip-accuracy]

Part 1, speed (bench_scene, probe at the origin inside it): per splat count and face size, a full probe (render
+ exact irradiance 16^2, the irradiance read back) on a renderer without a level of detail ("off") and, for each
k, on one with it; medians of GPU time (timestamps), wall time, the render's stages, the nodes drawn, and the
irradiance error of that probe against "off" (relative RMS, as the bake's search measures it).
Part 2, accuracy: the same error on the synthetic scenes (three 200k-splat shells, the room, the sample
environment), the guitar capture (tests/data, probe outside it) and samples/room.ply.
With --hold-clock a CUDA context (torch) keeps an NVIDIA GPU's SM clock up (shared/NOTES-vulkan-and-gpu.md); the
SM clock (NVML) is recorded per row.
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

from gs_ibl_addon.core import synthetic  # noqa: E402
from gs_ibl_addon.core.bake import default_probe_position, relative_rms  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe import filter_probe  # noqa: E402
from gs_ibl_addon.core.render.lod import build_lod  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
STAGES = ("preprocess", "lod_compact", "sort_depth", "emit", "sort_tiles", "ranges", "raster")


def probe(r: SplatRenderer, batch: ViewBatch, k: float) -> tuple[float, dict, np.ndarray]:
    """(GPU ms of render + filter, render stages, irradiance) of one probe."""
    res = r.render(batch, timestamps=True, wait=False, lod_k=k)
    pr = filter_probe(res.frame, 16, method="exact", roughness=None, read_radiance=False)
    t = res.timings_ms
    return t.get("total", 0.0) + pr.timings_ms.get("filter_gpu", 0.0), dict(t, filter=pr.timings_ms.get("filter_gpu", 0.0)), pr.irradiance


def timed(r: SplatRenderer, batch: ViewBatch, k: float, repeats: int) -> dict:
    warm_up(lambda: probe(r, batch, k), 0.3)
    walls, gpus, stages = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        g, st, irr = probe(r, batch, k)
        walls.append((time.perf_counter() - t0) * 1e3)
        gpus.append(g)
        stages.append(st)
    out = {"gpu_ms": statistics.median(gpus), "wall_ms": statistics.median(walls), "irr": irr}
    for s in STAGES + ("filter",):
        out[s] = statistics.median(x.get(s, 0.0) for x in stages)
    return out


def drawn(r: SplatRenderer, batch: ViewBatch, k: float) -> int:
    """Nodes drawn (in the cut and visible): the compacted count, read back after a render."""
    if r.lod is None:
        return r.scene_count
    r.render(batch, lod_k=k)
    return r.drawn


def accuracy_scenes() -> list[tuple[str, object, np.ndarray]]:
    out = [(f"shell_{name}", synthetic.shell_scene(fn, 200_000), np.zeros(3))
           for name, fn in synthetic.radiance_functions().items()]
    out.append(("room", synthetic.room_scene().scene, np.array([0.0, 0.0, 1.5])))
    out.append(("sample_env", synthetic.sample_environment(), np.array([0.0, 0.0, 1.0])))
    g = read_scene(os.path.join(ROOT, "tests", "data", "guitar.compressed.ply"))
    ext = float(np.max(np.percentile(g.positions, 95, 0) - np.percentile(g.positions, 5, 0)))
    out.append(("guitar", g, default_probe_position(g) + np.array([0.0, -1.0, 0.3]) * ext))
    out.append(("room.ply", read_scene(os.path.join(ROOT, "samples", "room.ply")), np.array([0.0, 0.0, 1.0])))
    return out


def save(path: str, rows: list[dict]) -> None:
    """This run's rows, the file rewritten (one run per CSV)."""
    if os.path.exists(path):
        os.remove(path)
    append_csv(path, rows)


def plot(rows: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    speed = [r for r in rows if r["part"] == "speed"]
    acc = [r for r in rows if r["part"] == "accuracy"]
    faces = sorted({r["face"] for r in speed})
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    ax = axes[0]
    for fi, face in enumerate(faces):
        for n, marker in zip(sorted({r["splats"] for r in speed}), "os^D"):
            sub = sorted((r for r in speed if r["face"] == face and r["splats"] == n), key=lambda r: r["k"])
            if not sub:
                continue
            ax.plot([max(r["err_pct"], 1e-4) for r in sub], [r["gpu_ms"] for r in sub], "-" + marker, color=f"C{fi}",
                    ms=5, label=f"{n / 1e6:g}M, {face}²")
            for r in sub:
                ax.annotate(f"k={r['k']:g}" if r["k"] else "off", (max(r["err_pct"], 1e-4), r["gpu_ms"]), fontsize=5)
    ax.axvline(0.5, color="grey", ls=":", label="0.5% target")
    ax.axhline(0.3, color="C3", ls=":", lw=0.8, label="0.3 ms (1M) / 1 ms (6M) targets")
    ax.axhline(1.0, color="C3", ls=":", lw=0.8)
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("irradiance error vs full detail (rel. RMS %; 'off' drawn at 1e-4)")
    ax.set_ylabel("full probe GPU ms (render + exact irradiance)")
    ax.set_title("bench_scene, probe inside: speed against error", fontsize=9)
    ax.grid(alpha=0.3, which="both"); ax.legend(fontsize=6, ncol=2)
    ax = axes[1]
    names = sorted({r["scene"] for r in acc})
    ks = sorted({r["k"] for r in acc})
    for fi, face in enumerate(sorted({r["face"] for r in acc})):
        for ki, k in enumerate(ks):
            ys = [next((max(r["err_pct"], 1e-4) for r in acc if r["scene"] == nm and r["face"] == face and r["k"] == k), np.nan)
                  for nm in names]
            ax.scatter(np.arange(len(names)) + 0.15 * (fi - 1.5), ys, marker="os^Dv"[ki % 5], color=f"C{fi}", s=14,
                       label=f"{face}², k={k:g}")
    ax.axhline(0.5, color="grey", ls=":")
    ax.set_yscale("log")
    ax.set_xticks(range(len(names)), names, rotation=30, fontsize=7)
    ax.set_ylabel("irradiance error vs full detail (rel. RMS %)")
    ax.set_title("accuracy scenes (0 drawn at 1e-4)", fontsize=9)
    ax.grid(alpha=0.3, which="both"); ax.legend(fontsize=5, ncol=4)
    r0 = rows[0]
    fig.suptitle(f"Level of detail: {r0['device']}, SM {r0['sm_mhz']} MHz, {r0['date']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="100000,1000000,6000000")
    ap.add_argument("--faces", default="32,64,128,256")
    ap.add_argument("--ks", default="0.25,0.5,1,2")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--hold-clock", action="store_true")
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--csv", default=os.path.join(ROOT, "out", "bench", "lod.csv"))
    ap.add_argument("--png", default="")
    ap.add_argument("--plot-csv", default="", help="only plot this CSV into --png")
    args = ap.parse_args()
    if args.plot_csv:
        import csv
        with open(args.plot_csv) as f:
            rows = [{k: (v if k in ("device", "date", "part", "scene", "sm_mhz") else float(v)) for k, v in r.items()}
                    for r in csv.DictReader(f)]
        plot(rows, args.png)
        return
    holder = hold_gpu_clock() if args.hold_clock else None
    ctx = get_context()
    date = datetime.date.today().isoformat()
    ks = [float(x) for x in args.ks.split(",")]
    faces = [int(x) for x in args.faces.split(",")]
    rows: list[dict] = []
    print(f"device: {ctx.device_name}; clock held by CUDA: {holder is not None}", flush=True)

    def row(part, scene, n, nodes, build_s, face, k, t, err, count):
        r = {"device": ctx.device_name, "date": date, "sm_mhz": gpu_clock(), "part": part, "scene": scene,
             "splats": n, "nodes": nodes, "build_s": round(build_s, 2), "face": face, "k": k, "drawn": count,
             "gpu_ms": round(t["gpu_ms"], 4) if t else "", "wall_ms": round(t["wall_ms"], 4) if t else "",
             **{f"{s}_ms": round(t[s], 4) if t else "" for s in STAGES + ("filter",)}, "err_pct": round(100 * err, 4)}
        rows.append(r)
        print(" ".join(f"{k}={v}" for k, v in r.items() if k not in ("device", "date")), flush=True)

    for n in [int(x) for x in args.counts.split(",")]:
        scene = bench_scene(n)
        tree = build_lod(scene)
        print(f"{n:,} splats: level of detail built in {tree.build_s:.1f} s, {tree.count:,} nodes "
              f"{tree.counts_by_level()}", flush=True)
        with SplatRenderer(scene, ctx) as full, SplatRenderer(scene, ctx, lod=tree) as r:
            del scene
            for face in faces:
                batch = ViewBatch.cubemap([0.0, 0.0, 0.0], face)
                t = timed(full, batch, 0.0, args.repeats)
                ref = t["irr"]
                row("speed", "bench_scene", n, tree.count, tree.build_s, face, 0.0, t, 0.0, n)
                for k in ks:
                    t = timed(r, batch, k, args.repeats)
                    row("speed", "bench_scene", n, tree.count, tree.build_s, face, k, t, relative_rms(t["irr"], ref),
                        drawn(r, batch, k))
        save(args.csv, rows)  # after each count, in case the run is cut short
    if not args.skip_accuracy:
        for name, scene, pos in accuracy_scenes():
            tree = build_lod(scene)
            with SplatRenderer(scene, ctx, lod=tree) as r:
                for face in faces:
                    batch = ViewBatch.cubemap(pos, face)
                    ref = probe(r, batch, 0.0)[2]
                    for k in ks:
                        row("accuracy", name, scene.count, tree.count, tree.build_s, face, k, None,
                            relative_rms(probe(r, batch, k)[2], ref), drawn(r, batch, k))
    save(args.csv, rows)
    if args.png:
        plot(rows, args.png)


if __name__ == "__main__":
    main()
