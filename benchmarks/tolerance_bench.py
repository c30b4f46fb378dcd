"""Settings from a tolerance against the speed/accuracy sweep: is the chosen setting on the Pareto front, and within
the tolerance?

Run: python benchmarks/tolerance_bench.py [--scenes a,b] [--faces 32,64,...] [--out DIR]

Scenes: every synthetic scene of core/synthetic.py (the `sky`, `walls` and `sun` shells of 50k splats with the probe
at their centre, `room` at (0, 0, 1.5), `sample_env` at (0, 0, 1), a `random` cloud of 20k splats around its
centre), the bundled sample `samples/room.ply` and the real capture `tests/data/guitar.compressed.ply`, both with
the probe where the command line puts it (the splats' opacity-weighted centre).

Ground truth: the scene rendered at --truth-face (1024^2, face by face), holes filled as bakes fill them, and
integrated exactly (GPU, downsampled to 128^2) at the irradiance size compared.

Sweep (rows kind=sweep): radiance face x level of detail (off, auto with k = 1) x filter (exact, sh = SH order 2,
box, conv = cosine convolution 64x16), irradiance 16^2. One render per (face, lod), its holes filled, then every
filter on that cube. Cost = render GPU time + filter GPU time (timestamps; on lavapipe the "GPU" is the CPU).
Tolerance runs (kind=tolerance): bake_probe(face_size=0, irradiance_size=0, tolerance=T) for each --tolerances T
with lod off, and at 1% with lod auto; their cost is the sum of the sweep's exact-filter costs over the faces they
rendered (plus bake_probe's own wall time), their true error is against the truth at the irradiance size chosen.

Errors: rel RMS per channel weighted by texel solid angle, worst channel (`err`, the docs' metric), and pooled
(`err_pooled`, bake.relative_rms: what the estimate estimates). A sweep point is on the front when no other point of
its scene is both cheaper and more exact (by `err`).
Writes DIR/tolerance_<device>.csv, DIR/tolerance_<device>.md and docs/tolerance-pareto.png (--chart).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import re
import sys
import time
from dataclasses import replace

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)

from gs_ibl_addon.core import cubemap, synthetic  # noqa: E402
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe, default_probe_position, relative_rms  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe import filter_probe  # noqa: E402
from gs_ibl_addon.core.probe.holes import fill_holes  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

T0 = time.perf_counter()
METHODS = ("exact", "sh", "box", "convolve")
SWEEP_M = 16


def say(msg: str) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s] {msg}", flush=True)


def scenes() -> list[tuple[str, object, np.ndarray]]:
    out = [(name, synthetic.shell_scene(fn, 50_000), np.zeros(3)) for name, fn in synthetic.radiance_functions().items()]
    out.append(("room", synthetic.room_scene().scene, np.array([0.0, 0.0, 1.5])))
    out.append(("sample_env", synthetic.sample_environment(), np.array([0.0, 0.0, 1.0])))
    rnd = synthetic.random_scene(20_000, seed=0)
    out.append(("random", rnd, default_probe_position(rnd)))
    for name, path in (("samples/room.ply", "samples/room.ply"), ("guitar (real)", "tests/data/guitar.compressed.ply")):
        s = read_scene(os.path.join(ROOT, path))
        out.append((name, s, default_probe_position(s)))
    return out


def errors(a: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """(worst channel of the solid-angle weighted rel RMS, pooled rel RMS)."""
    w = cubemap.texel_solid_angles(a.shape[1])[None, :, :, None]
    rms = np.sqrt(np.sum(w * (a - t) ** 2, axis=(0, 1, 2)) / np.sum(w * t * t, axis=(0, 1, 2)))
    return float(rms.max()), relative_rms(a, t)


def render_cube(r: SplatRenderer, pos: np.ndarray, face: int, lod_k: float) -> tuple[np.ndarray, float]:
    cube = ViewBatch.cubemap(pos, face)
    if face < 1024:
        res = r.render(cube, timestamps=True, lod_k=lod_k)
        return np.stack(res.images), res.timings_ms.get("total", 0.0)
    images, ms = [], 0.0
    for view in cube.views:
        res = r.render(replace(cube, views=(view,)), timestamps=True, lod_k=lod_k)
        images += res.images
        ms += res.timings_ms.get("total", 0.0)
    return np.stack(images), ms


def filtered(cube: np.ndarray, method: str, m: int, ctx, **extra) -> tuple[np.ndarray, float]:
    t = time.perf_counter()
    p = filter_probe(cube[..., :3], irradiance_size=m, method=method, roughness=None, use_gpu=True,
                     vk_context=ctx, **extra)
    gpu = p.timings_ms.get("filter_gpu")
    return p.irradiance, gpu if gpu else (time.perf_counter() - t) * 1e3


def pareto(points: list[dict]) -> None:
    """Mark each point's ``front``: no other point is both cheaper (or as cheap) and more exact."""
    for p in points:
        p["front"] = not any(q is not p and q["cost_ms"] <= p["cost_ms"] and q["err"] < p["err"]
                             and (q["cost_ms"] < p["cost_ms"] or q["err"] < p["err"]) for q in points)


def run_scene(name, scene, pos, args, ctx, device, date, load) -> list[dict]:
    r = SplatRenderer(scene, ctx, lod=True)
    rows: list[dict] = []
    try:
        t = time.perf_counter()
        cube, _ = render_cube(r, pos, args.truth_face, 0.0)
        cube, _fill = fill_holes(cube, "mean", (0.0, 0.0, 0.0), None)
        truth = {m: filtered(cube, "exact", m, ctx, downsample_to=128)[0] for m in (8, 16, 32)}
        del cube
        say(f"  truth {args.truth_face}^2: {time.perf_counter() - t:.1f} s")
        base = dict(device=device, date=date, load1=load, scene=name, splats=scene.count)
        exact_cost: dict[int, float] = {}
        for lod, k in (("off", 0.0), ("auto", 1.0)):
            for face in args.faces:
                cube, render_ms = render_cube(r, pos, face, k)
                cube, _fill = fill_holes(cube, "mean", (0.0, 0.0, 0.0), None)
                for method in METHODS:
                    irr, filter_ms = filtered(cube, method, SWEEP_M, ctx)
                    err, pooled = errors(irr, truth[SWEEP_M])
                    rows.append({**base, "kind": "sweep", "face": face, "lod": lod, "method": method,
                                 "irradiance": SWEEP_M, "render_ms": render_ms, "filter_ms": filter_ms,
                                 "cost_ms": render_ms + filter_ms, "err": err, "err_pooled": pooled})
                    if method == "exact" and lod == "off":
                        exact_cost[face] = render_ms + filter_ms
                say(f"  {face}^2 lod {lod}: render {render_ms:.0f} ms, exact "
                    f"{next(x['err'] for x in rows if x['face'] == face and x['lod'] == lod and x['method'] == 'exact'):.3%}")
        pareto([x for x in rows if x["kind"] == "sweep"])
        runs = [(t, "off") for t in args.tolerances] + [(0.01, "auto")]
        for tol, lod in runs:
            p = bake_probe(scene, pos, ProbeSettings(tolerance=tol, irradiance_size=0, lod=lod), renderer=r)
            st, plan = p.settings, p.settings["tolerance_plan"]
            m = int(st["irradiance_size"])
            err, pooled = errors(p.irradiance, truth[m])
            faces = [t_["face_size"] for t_ in st["face_size_trials"]]
            extra = len(faces) if "lod_error" in plan else 0  # the lod check renders the first face twice more
            cost = sum(exact_cost.get(f, float("nan")) for f in faces) + extra * exact_cost.get(faces[0], 0.0)
            rows.append({**base, "kind": "tolerance", "tolerance": tol, "face": st["face_size"], "lod": plan["lod"],
                         "method": st["method"], "irradiance": m, "faces_rendered": " ".join(map(str, faces)),
                         "estimate": plan["estimated_error"], "met_estimate": plan["met"], "err": err,
                         "err_pooled": pooled, "cost_ms": cost, "bake_wall_ms": p.timings_ms["bake_wall"],
                         "between_texels": plan.get("irradiance_between_texels", {}).get(str(m)),
                         "sh_error": plan.get("sh_error"), "lod_error": plan.get("lod_error")})
            say(f"  tolerance {tol:g} lod {lod}: faces {faces} -> {st['face_size']}^2, M {m}, estimate "
                f"{plan['estimated_error']:.3%}, true {err:.3%} (pooled {pooled:.3%}), wall "
                f"{p.timings_ms['bake_wall']:.0f} ms")
    finally:
        r.close()
    return rows


def summary(rows: list[dict]) -> str:
    """Per tolerance run: the setting chosen, its estimated and true error, the cost of the whole search and of the
    chosen setting alone (its sweep point), whether that point is on the front, and the cheapest sweep point within
    the tolerance."""
    lines = ["| scene | tolerance | faces rendered | chosen: face, irradiance, method, lod | estimated error | "
             "true error (worst channel / pooled) | search cost, GPU ms (wall) | chosen setting alone: GPU ms, "
             "on the front? | cheapest sweep point within the tolerance |", "|---" * 9 + "|"]
    for r in (x for x in rows if x["kind"] == "tolerance"):
        sweep = [x for x in rows if x["kind"] == "sweep" and x["scene"] == r["scene"]]
        ok = [x for x in sweep if x["err"] <= r["tolerance"]]
        best = min(ok, key=lambda x: x["cost_ms"]) if ok else None
        mine = next((x for x in sweep if x["face"] == r["face"] and x["method"] == r["method"]
                     and x["lod"] == r["lod"]), None)
        if mine is None:
            alone = "not in the sweep"
        else:
            alone = f"{mine['cost_ms']:.0f}, " + ("on it" if mine["front"] else "off it: " + ", ".join(
                f"{x['face']}² {x['method']} lod {x['lod']} ({x['err']:.3%}, {x['cost_ms']:.0f})"
                for x in sorted((x for x in sweep if x["cost_ms"] < mine["cost_ms"] and x["err"] < mine["err"]),
                                key=lambda x: x["cost_ms"])[:2]))
        lines.append(f"| {r['scene']} | {r['tolerance']:g}{', lod auto asked' if r['lod_error'] is not None else ''}"
                     f" | {r['faces_rendered']} | {r['face']}², {r['irradiance']}², {r['method']}, {r['lod']} | "
                     f"{r['estimate']:.3%} | {r['err']:.3%} / {r['err_pooled']:.3%} | {r['cost_ms']:.0f} "
                     f"({r['bake_wall_ms']:.0f}) | {alone} | "
                     + (f"{best['face']}² {best['method']} lod {best['lod']}: {best['err']:.3%}, "
                        f"{best['cost_ms']:.0f} ms" if best else "none") + " |")
    return "\n".join(lines)


def chart(rows: list[dict], path: str, device: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(dict.fromkeys(r["scene"] for r in rows))
    cols = 3
    fig, axes = plt.subplots((len(names) + cols - 1) // cols, cols, figsize=(5 * cols, 3.8 * ((len(names) + 2) // cols)),
                             squeeze=False)
    colours = {"exact": "tab:purple", "sh": "tab:blue", "box": "tab:green", "convolve": "tab:red"}
    for ax, name in zip(axes.flat, names):
        sweep = [r for r in rows if r["scene"] == name and r["kind"] == "sweep"]
        for method, c in colours.items():
            for lod, mk in (("off", "o"), ("auto", "^")):
                pts = [r for r in sweep if r["method"] == method and r["lod"] == lod]
                ax.scatter([p["cost_ms"] for p in pts], [p["err"] for p in pts], c=c, marker=mk, s=14, alpha=0.6,
                           label=f"{method}, lod {lod}" if name == names[0] else None)
        front = sorted((r for r in sweep if r["front"]), key=lambda r: r["cost_ms"])
        ax.plot([r["cost_ms"] for r in front], [r["err"] for r in front], "k-", lw=0.8)
        for r in (r for r in rows if r["scene"] == name and r["kind"] == "tolerance"):
            ax.scatter([r["cost_ms"]], [r["err"]], marker="*", s=120, c="gold", edgecolors="k", zorder=5)
            ax.annotate(f"{r['tolerance']:g}{' lod' if r['lod_error'] is not None else ''}",
                        (r["cost_ms"], r["err"]), fontsize=7, xytext=(4, 4), textcoords="offset points")
            ax.axhline(r["tolerance"], color="gold", lw=0.5, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("GPU ms (render + filter)", fontsize=8)
        ax.set_ylabel("irradiance rel RMS vs truth", fontsize=8)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.legend(loc="lower right", fontsize=7)
    fig.suptitle(f"Tolerance-chosen settings (stars; cost = sum of their steps) against the sweep, {device}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=None, help="comma-separated scene names (default: all)")
    ap.add_argument("--faces", default="32,64,128,256,512", help="radiance faces of the sweep")
    ap.add_argument("--tolerances", default="0.05,0.01,0.002", help="tolerances of the bake_probe runs")
    ap.add_argument("--truth-face", type=int, default=1024)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"), help="folder of the CSV and table")
    ap.add_argument("--chart", default=os.path.join(ROOT, "docs", "tolerance-pareto.png"))
    args = ap.parse_args()
    args.faces = [int(x) for x in args.faces.split(",")]
    args.tolerances = [float(x) for x in args.tolerances.split(",")]
    ctx = get_context()
    device = ctx.device_name
    slug = re.sub(r"[^a-z0-9]+", "-", device.lower()).strip("-")
    date = datetime.date.today().isoformat()
    wanted = set(args.scenes.split(",")) if args.scenes else None
    rows: list[dict] = []
    for name, scene, pos in scenes():
        if wanted and name not in wanted:
            continue
        load = os.getloadavg()[0]
        say(f"scene {name}: {scene.count:,} splats, probe at {np.round(pos, 3).tolist()}, load {load:.1f}")
        rows += run_scene(name, scene, pos, args, ctx, device, date, load)
        write(rows, args, slug, device)
    say("done")


def write(rows: list[dict], args, slug: str, device: str) -> None:
    os.makedirs(args.out, exist_ok=True)
    fields = list(dict.fromkeys(k for r in rows for k in r))
    with open(os.path.join(args.out, f"tolerance_{slug}.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    text = summary(rows)
    with open(os.path.join(args.out, f"tolerance_{slug}.md"), "w") as fh:
        fh.write(text + "\n")
    print(text)
    if args.chart:
        chart(rows, args.chart, device)


if __name__ == "__main__":
    main()
