"""The light volume's accuracy and cost in core, without Blender (issue 37 item 5).

Run:  .venv/bin/python benchmarks/volume_bench.py [--points 256] [--configs 0.6:16:0,0.4:16:0,0.6:16:0:512]
      [--budgets 256,512,1024,2048]
      [--out-csv docs/bench/volume_lavapipe.csv] [--png docs/img/volume_bench.png]

The sample room (samples/room.ply) with white spheres (r 0.25) at auto_light_bench.py's five places. At --points
shading points on each sphere (Fibonacci, normals outward) the reference is a dense per-point probe: the point's own
32^2 cube (every splat) and the exact cosine integral of its texels at the point's normal. Against it, per point:
- world: the World probe (order-2 SH at auto_light_bench's PROBE, 64^2) for every point;
- auto: Lighting Auto of today: the 9-point measurement with the World probe's place, then the World probe, the mesh's
  own probe or its order-2 SH grid (3^3 or 5^3), as auto_bake_core.py / blender/lighting do;
- volume S:F:K[:B]: one light volume over all five spheres (volume_region.plan_volume, spacing S m), F^2 faces,
  level of detail k = K (0: every splat), read by volume.sample; with B, bricks (volume_refine.bake_refined) in the
  cells the spheres touch, up to B probes in all;
- volume at auto's nodes: a volume per sphere on the nodes of Auto's grid for it (3^3, or 5^3 where Auto takes it),
  16^2 faces: octahedral maps and visibility against order-2 SH at equal density.
Numbers per place and method: the per-point luminance error relative to the reference (mean, 95th percentile) and
the mean of the camera-facing half's RGB, ours / reference (auto_light_bench's cell: within 3% in all channels).
The lamp's cell is a mean over a light that falls off across the sphere (E/pi ~12 at the top point, ~1 at the side),
led by the few points nearest the lamp: World's cell there read 0.45 at 32 points, 0.59 at 48, 0.57 at 64, 0.54 at
128, 0.52 at 256, 0.51 at 512 (lavapipe; the per-point error mean 0.237-0.241 throughout). So the default is 256,
and every row records its point count: rows of two runs compare only at the same count (issue 37: 32 points on
lavapipe against 64 on the H100 read as a 15% device difference; at 64 points lavapipe gives the H100's lamp rows
to 4 digits).

Cost: the World probe's bake as the panel's Bake does it (bake_probe with the panel's defaults, warm), and the
volume's bake as Lighting Volume runs it (the light's measurement, the grid at its share of the budget, centres
and bricks) over 3 meshes (centre, window, table) and 10 meshes (the five
places and five more about the room); ratio = (World + volume) / World, issue 37's target <= 2x and <= 4x. Also
Lighting Auto's measurement + grids for the same 3 meshes. All on one renderer built with a level of detail (the
World probe renders every splat of it). The load average is on every row: timings on a shared CPU are noisy; the
ratios are measured in the same run. Every submission of the cost runs is timestamped (ctx.stamp_all): a volume
row also has its GPU time, host = wall - GPU, and its submissions (issue 38's split).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)
from auto_light_bench import PLACES, PROBE  # noqa: E402
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe import volume as vol  # noqa: E402
from gs_ibl_addon.core.probe import volume_bake  # noqa: E402
from gs_ibl_addon.core.probe.auto_light import auto_light, measure_bake, mesh_grid  # noqa: E402
from gs_ibl_addon.core.probe.grid import eval_irradiance  # noqa: E402
from gs_ibl_addon.core.probe.variation import LUMINANCE  # noqa: E402
from gs_ibl_addon.core.probe.volume_bake import bake_volume, point_irradiance  # noqa: E402
from gs_ibl_addon.core.probe.volume_refine import bake_light_volume, bake_refined  # noqa: E402
from gs_ibl_addon.core.probe.volume_region import plan_volume  # noqa: E402
from gs_ibl_addon.core.render.renderer import BAKE_KEEP_SHARE, SplatRenderer  # noqa: E402
from gs_ibl_addon.core.stage_times import StageTimes, stages  # noqa: E402
from gs_ibl_addon.core.synthetic import fibonacci_sphere  # noqa: E402

RADIUS = 0.25
REF_FACE = 32
TOLERANCE = 0.05  # the panel's Variation Tolerance (Auto)
MORE_PLACES = [(-1.5, 1.5, 1.0), (1.5, 1.0, 1.0), (0.8, -1.8, 1.2), (-2.0, -1.8, 1.5), (2.0, -0.8, 0.6)]
COST_SETS = {"3 meshes": ["centre", "window", "table"], "10 meshes": list(PLACES) + MORE_PLACES}


def centre(place: str) -> np.ndarray:
    p = PLACES[place]
    c = np.array(p["centre"], np.float64)
    if p.get("rest_on") is not None:  # resting on the table top, as auto_light_scene.py places it
        c[2] = p["rest_on"] + 0.005 + RADIUS
    return c


def sphere_points(place: str, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, normals, camera-facing mask) on the sphere at ``place``."""
    d = fibonacci_sphere(n)
    c = centre(place)
    facing = d @ (np.asarray(PLACES[place]["camera"]) - c) > 0
    return c + RADIUS * d, d, facing


def reference(r: SplatRenderer, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """E/pi at each point and normal: the point's own cube, integrated exactly against the cosine lobe."""
    return point_irradiance(r, pts, nrm, REF_FACE)


def auto_today(r: SplatRenderer, place: str, pts: np.ndarray, nrm: np.ndarray):
    """(E/pi at the points from Lighting Auto's choice, the choice)."""
    c = centre(place)
    light = auto_light(r, PROBE, [(c - RADIUS, c + RADIUS)], [place], TOLERANCE)
    kind = light.choices[0].kind
    if kind == "grid":
        kind = f"grid {light.grids[0][0].shape[0]}^3"
    return eval_irradiance(light.coefficients_at(0, pts), nrm), kind


def errors(got: np.ndarray, want: np.ndarray, facing: np.ndarray) -> dict:
    lg, lw = got @ LUMINANCE, want @ LUMINANCE
    e = np.abs(lg - lw) / np.maximum(lw, 1e-9)
    ratio = got[facing].mean(0) / want[facing].mean(0)
    return {"err_mean": float(e.mean()), "err_p95": float(np.quantile(e, 0.95)),
            "cell_r": float(ratio[0]), "cell_g": float(ratio[1]), "cell_b": float(ratio[2]),
            "cell_ok": bool(np.all(np.abs(ratio - 1) <= 0.03))}


def boxes_of(names) -> list:
    cs = [centre(n) if isinstance(n, str) else np.asarray(n, np.float64) for n in names]
    return [(c - RADIUS, c + RADIUS) for c in cs]


def accuracy(r: SplatRenderer, n_points: int, configs) -> list[dict]:
    rows = []
    d_world = measure_bake(r)(np.asarray(PROBE, np.float64)[None])[0]
    data = {p: sphere_points(p, n_points) for p in PLACES}
    t0 = time.perf_counter()
    refs = {p: reference(r, *data[p][:2]) for p in PLACES}
    print(f"references: {len(PLACES) * n_points} per-point probes in {time.perf_counter() - t0:.1f} s", flush=True)
    volumes = {}
    for cfg in configs:
        spacing, face, k = cfg[:3]
        plan = plan_volume(boxes_of(PLACES), spacing, budget=4096)
        t0 = time.perf_counter()
        v = (bake_volume(r, plan.spec, face_size=face, lod_k=k) if len(cfg) == 3 else
             bake_refined(r, plan.spec, int(cfg[3]), boxes=boxes_of(PLACES), face_size=face, lod_k=k))
        volumes[cfg] = (v, plan, time.perf_counter() - t0)
        print(f"volume {':'.join(f'{x:g}' for x in cfg)}: {plan.messages[-1]}, {volumes[cfg][2]:.1f} s, "
              f"{v.timings['probes']} probes {v.report}", flush=True)
    for p in PLACES:
        pts, nrm, facing = data[p]
        want = refs[p]
        rows.append({"place": p, "method": "world", **errors(eval_irradiance(d_world, nrm), want, facing)})
        got, kind = auto_today(r, p, pts, nrm)
        rows.append({"place": p, "method": f"auto ({kind})", **errors(got, want, facing)})
        # the same nodes as Auto's grid for this mesh (3^3 or 5^3 over its shrunk box), as a volume: octahedral maps and
        # visibility against order-2 SH at equal density
        c = centre(p)
        spec = mesh_grid(c - RADIUS, c + RADIUS, 2.0 if kind == "grid 5^3" else 0.0)
        t0 = time.perf_counter()
        brick = bake_volume(r, spec, face_size=16)
        rows.append({"place": p, "method": "volume at auto's nodes", "probes": spec.count,
                     "bake_s": round(time.perf_counter() - t0, 2), **errors(vol.sample(brick, pts, nrm), want, facing)})
        for cfg, (v, _plan, secs) in volumes.items():
            name = "volume " + ":".join(f"{x:g}" for x in cfg[:3]) + (f" + bricks to {cfg[3]:g}" if len(cfg) > 3
                                                                       else "")
            rows.append({"place": p, "method": name, "probes": v.timings["probes"],
                         "bake_s": round(secs, 2), **errors(vol.sample(v, pts, nrm), want, facing)})
    return rows


def budget_sweep(r: SplatRenderer, n_points: int, budgets, faces=(volume_bake.DEFAULT_FACE,)) -> list[dict]:
    """Accuracy against time per Volume Probes budget and probe face size, the bake as Lighting Volume runs it over
    the five spheres (the light's measurement, the grid at GRID_SHARE, centres and bricks), warm: one row per
    budget, face and place."""
    data = {p: sphere_points(p, n_points) for p in PLACES}
    refs = {p: reference(r, *data[p][:2]) for p in PLACES}
    rows = []
    for face in faces:
        for budget in budgets:
            # timed as Blender's second bake of a scene: the first made the shapes' recordings, and trim() after it
            # gave back what its batches grew (blender/lighting/volume.py _bake)
            bake_light_volume(r, boxes_of(PLACES), budget, face_size=face)
            r.trim(BAKE_KEEP_SHARE)
            t0 = time.perf_counter()
            v = bake_light_volume(r, boxes_of(PLACES), budget, face_size=face)[1]
            secs = time.perf_counter() - t0
            r.trim(BAKE_KEEP_SHARE)
            print(f"budget {budget}, {face}^2 faces: {v.timings['probes']} probes, {secs:.2f} s; {v.report[:1]}",
                  flush=True)
            for p in PLACES:
                pts, nrm, facing = data[p]
                rows.append({"budget": budget, "face": face, "place": p, "probes": v.timings["probes"],
                             "bake_s": round(secs, 3), "load": round(os.getloadavg()[0], 2),
                             **errors(vol.sample(v, pts, nrm), refs[p], facing)})
    return rows


def plot_budgets(rows: list[dict], path: str, device: str) -> None:
    """Worst camera-half error over the five places, and the mean per-point error, against the bake's time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for i, face in enumerate(dict.fromkeys(r["face"] for r in rows)):
        rs = [r for r in rows if r["face"] == face]
        budgets = list(dict.fromkeys(r["budget"] for r in rs))
        t = [np.median([r["bake_s"] for r in rs if r["budget"] == b]) * 1e3 for b in budgets]
        worst = [100 * max(max(abs(r[f"cell_{c}"] - 1) for c in "rgb") for r in rs if r["budget"] == b)
                 for b in budgets]
        mean = [100 * np.mean([r["err_mean"] for r in rs if r["budget"] == b]) for b in budgets]
        ax.plot(t, worst, "o-", color=f"C{i}", label=f"{face}² faces: worst camera-half mean, five places")
        ax.plot(t, mean, "s--", color=f"C{i}", label=f"{face}² faces: per-point error, mean over the places")
        for x, y, b in zip(t, worst, budgets):
            ax.annotate(f"{b}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.axhline(3, color="k", lw=0.7, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel(f"Lighting Volume bake over the five spheres, ms ({device})")
    ax.set_ylabel("error, %")
    ax.set_title("Volume Probes: accuracy against time (labels: the budget; target 3%, dotted)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def cost(r: SplatRenderer, scene, repeats: int) -> list[dict]:
    r.ctx.stamp_all = True  # every submission timestamped: the volume's GPU time beside its wall (issue 38's split)
    try:
        return _cost(r, scene, repeats)
    finally:
        r.ctx.stamp_all = False  # the budget sweep after it times its bakes as a user's run them


def _cost(r: SplatRenderer, scene, repeats: int) -> list[dict]:
    def world() -> float:
        t0 = time.perf_counter()
        bake_probe(None, np.asarray(PROBE, np.float64), ProbeSettings(), renderer=r, host_splats=scene)
        return time.perf_counter() - t0

    def volume(names, keep: float = BAKE_KEEP_SHARE) -> tuple[float, int, dict]:
        """Lighting Volume's bake as blender/lighting/volume.py runs it: the light's measurement and the grid's plan
        (its share of the budget), then grid, centres and bricks, on a renderer trimmed as Blender's bakes leave it
        (``keep``: trim's keep_within; 0 gives every batch's buffers back). (wall s, probes, its GPU / host ms and
        submissions)."""
        timings: dict = {}
        r.trim(keep)
        with StageTimes(r.ctx, timings).stage("volume"):
            v = bake_light_volume(r, boxes_of(names))[1]
        t = stages(timings)["volume"]
        split = {"gpu_ms": round(t["gpu"], 2), "host_ms": round(t["host"], 2), "submits": int(t["submits"])}
        return t["wall"] / 1e3, v.timings["probes"], split

    def auto(names) -> float:
        t0 = time.perf_counter()
        auto_light(r, PROBE, boxes_of(names), names, TOLERANCE)
        return time.perf_counter() - t0

    world()  # warm-up: pipelines, allocations
    volume(COST_SETS["3 meshes"])
    rows = []
    for _ in range(repeats):
        tw = world()
        for label, names in COST_SETS.items():
            tv, probes, split = volume(names)
            rows.append({"meshes": label, "world_s": round(tw, 3), "volume_s": round(tv, 3), "probes": probes,
                         "ratio": round((tw + tv) / tw, 2), "load": round(os.getloadavg()[0], 2), **split})
            print(rows[-1], flush=True)
        volume_bake.GPU_MAPS = False  # A/B: the maps from cubes read back (a GPU device's default makes them on it)
        tv, probes, split = volume(COST_SETS["3 meshes"])
        volume_bake.GPU_MAPS = None
        rows.append({"meshes": "3 meshes, host maps", "world_s": round(tw, 3), "volume_s": round(tv, 3),
                     "probes": probes, "ratio": round((tw + tv) / tw, 2), "load": round(os.getloadavg()[0], 2),
                     **split})
        print(rows[-1], flush=True)
        # A/B: every batch's buffers given back before the bake (a large scene's, past BAKE_KEEP_SHARE, and every
        # bake's before 2026-12-06), with the room made before recording (SplatRenderer._presize) and without it (the
        # first batch of each bake drawn twice, as before)
        presize = SplatRenderer._presize
        for label, room in (("given back", presize), ("given back, first batch drawn twice", lambda *_args: None)):
            SplatRenderer._presize = room
            try:
                tv, probes, split = volume(COST_SETS["3 meshes"], keep=0.0)
            finally:
                SplatRenderer._presize = presize
            rows.append({"meshes": f"3 meshes, {label}", "world_s": round(tw, 3), "volume_s": round(tv, 3),
                         "probes": probes, "ratio": round((tw + tv) / tw, 2), "load": round(os.getloadavg()[0], 2),
                         **split})
            print(rows[-1], flush=True)
        ta = auto(COST_SETS["3 meshes"])
        rows.append({"meshes": "3 meshes, Auto today", "world_s": round(tw, 3), "volume_s": round(ta, 3),
                     "probes": 0, "ratio": round((tw + ta) / tw, 2), "load": round(os.getloadavg()[0], 2)})
        print(rows[-1], flush=True)
    return rows


def write_csv(path: str, rows: list[dict], extra: dict) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    keys = list(extra) + sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k)
                                if k in rows[0] else 99)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for row in rows:
            w.writerow({**extra, **row})


def plot(acc: list[dict], costs: list[dict], path: str, device: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401 (matplotlib.ticker below)
    methods = list(dict.fromkeys(r["method"].split(" (")[0] for r in acc))
    places = list(PLACES)
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 4.8), gridspec_kw={"width_ratios": [2.2, 1]})
    width = 0.8 / len(methods)
    for i, m in enumerate(methods):
        vals = [100 * next(float(r["err_mean"]) for r in acc if r["place"] == p and r["method"].split(" (")[0] == m)
                for p in places]
        a.bar(np.arange(len(places)) + i * width, vals, width, label=m)
    a.set_xticks(np.arange(len(places)) + 0.4 - width / 2, places)
    a.set_ylabel("per-point irradiance error, mean (%)")
    a.set_yscale("log")
    a.set_yticks([1, 2, 3, 5, 10, 20, 50], ["1", "2", "3", "5", "10", "20", "50"])
    a.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    a.axhline(3, color="k", lw=0.8, ls="--")
    a.set_title("White spheres in the sample room vs dense per-point probes")
    a.legend(fontsize=7, ncol=2)
    labels = list(dict.fromkeys(c["meshes"] for c in costs))
    ratios = [np.median([float(c["ratio"]) for c in costs if c["meshes"] == m]) for m in labels]
    b.barh(range(len(labels)), ratios, color=[f"C{i}" for i in range(len(labels))])  # long labels read sideways
    for i, v in enumerate(ratios):
        b.text(v, i, f" {v:.1f}x", ha="left", va="center", fontsize=8)
    b.set_yticks(range(len(labels)), labels, fontsize=8)
    b.invert_yaxis()
    b.set_xlim(0, 1.15 * max(ratios))
    b.set_xlabel("whole bake / World-probe-only bake (median)")
    b.axvline(2, color="k", lw=0.8, ls="--")
    b.axvline(4, color="k", lw=0.8, ls=":")
    b.set_title(f"Cost, {device}\n(targets 2x and 4x, lines)", fontsize=10)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=256, help="shading points per sphere")
    ap.add_argument("--configs", default="0.6:16:0,0.4:16:0,0.6:16:0:512,1.0:16:0:512",
                    help="volume configurations spacing:face:lod_k[:budget], comma separated (a budget: bricks up "
                         "to that many probes in all, volume_refine.py)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--budgets", default="256,512,1024,2048",
                    help="Volume Probes budgets for the accuracy-against-time sweep ('' skips it)")
    ap.add_argument("--faces", default=str(volume_bake.DEFAULT_FACE),
                    help="probe cube faces for the budget sweep, comma separated (e.g. 16,32)")
    ap.add_argument("--out-csv", default=None)
    ap.add_argument("--png", default=os.path.join(REPO, "docs", "img", "volume_bench.png"))
    ap.add_argument("--replot", metavar="CSV", help="redraw the chart from a run's CSVs (CSV_accuracy.csv and "
                    "CSV_cost.csv, e.g. docs/bench/volume_nvidia-h100.csv) and stop")
    a = ap.parse_args()
    if a.replot:
        def rows(path):
            with open(path, newline="") as f:
                return list(csv.DictReader(f))
        acc, costs = (rows(a.replot.replace(".csv", f"_{k}.csv")) for k in ("accuracy", "cost"))
        plot(acc, costs, a.png, costs[0]["device"].lower().replace(" ", "-"))
        print(f"wrote {a.png}")
        return
    configs = [tuple(float(x) if i != 1 else int(x) for i, x in enumerate(c.split(":"))) for c in
               a.configs.split(",")]
    volume_bake.GPU_MAPS = None  # the default: the maps on a GPU device, numpy on a CPU one; its A/B row below
    scene = read_scene(os.path.join(REPO, "samples", "room.ply"))
    t0 = time.perf_counter()
    r = SplatRenderer(scene, lod=True)
    print(f"renderer with a level of detail: {time.perf_counter() - t0:.1f} s ({scene.count:,} splats)")
    name = r.ctx.device_name.lower()
    dev = "lavapipe" if "llvmpipe" in name else name.replace(" ", "-")
    extra = {"date": datetime.date.today().isoformat(), "device": r.ctx.device_name, "points": a.points}
    acc = [] if a.skip_accuracy else accuracy(r, a.points, configs)
    costs = cost(r, scene, a.repeats)
    sweep = budget_sweep(r, a.points, [int(x) for x in a.budgets.split(",") if x],
                         [int(x) for x in a.faces.split(",") if x]) if a.budgets else []
    r.close()
    base = a.out_csv or os.path.join(REPO, "docs", "bench", f"volume_{dev}.csv")
    if sweep:
        write_csv(base.replace(".csv", "_budgets.csv"), sweep, extra)
        plot_budgets(sweep, os.path.join(os.path.dirname(a.png), "volume_budgets.png"), dev)
        print("\n| face | budget | probes | bake s | places within 3% | worst camera half | per-point mean |\n"
              "|---|---|---|---|---|---|---|")
        for f, b in dict.fromkeys((x["face"], x["budget"]) for x in sweep):
            rs = [x for x in sweep if x["budget"] == b and x["face"] == f]
            worst = max(max(abs(x[f"cell_{c}"] - 1) for c in "rgb") for x in rs)
            print(f"| {f}² | {b} | {rs[0]['probes']} | {rs[0]['bake_s']} | {sum(x['cell_ok'] for x in rs)} of "
                  f"{len(rs)} | {100 * worst:.1f}% | {100 * np.mean([x['err_mean'] for x in rs]):.1f}% |")
    if acc:
        write_csv(base.replace(".csv", "_accuracy.csv"), acc, extra)
        print(f"\n{a.points} points per sphere")
        print("\n| place | method | per-point error mean | p95 | camera half R/G/B (ours/ref) | cell |")
        print("|---|---|---|---|---|---|")
        for row in acc:
            print(f"| {row['place']} | {row['method']} | {100 * row['err_mean']:.1f}% | {100 * row['err_p95']:.1f}% | "
                  f"{row['cell_r']:.3f} / {row['cell_g']:.3f} / {row['cell_b']:.3f} | "
                  f"{'ok' if row['cell_ok'] else 'out'} |")
    write_csv(base.replace(".csv", "_cost.csv"), costs, extra)
    print("\n| meshes | World s | volume (or Auto) s | volume GPU / host ms, submits | probes | ratio | load |\n"
          "|---|---|---|---|---|---|---|")
    for c in costs:
        split = f"{c['gpu_ms']} / {c['host_ms']}, {c['submits']}" if "gpu_ms" in c else "–"
        print(f"| {c['meshes']} | {c['world_s']} | {c['volume_s']} | {split} | {c['probes']} | {c['ratio']}x | "
              f"{c['load']} |")
    if acc:
        plot(acc, costs, a.png, dev)
        print(f"wrote {a.png}")


if __name__ == "__main__":
    main()
