"""Probe irradiance: speed against accuracy, over methods x radiance face size x irradiance size.

Run: python benchmarks/accuracy_bench.py [--quick] [--out DIR] [--repeats 3]
Scenes are rendered by our GPU splat renderer: a shell_scene of each synthetic.radiance_functions() ('sky', 'walls',
'sun'), a room_scene (with its window and skylight holes) and sample_environment(). Each is rendered once per face
size; every filter configuration then runs on that cube (on the GPU where it has a GPU version; SH orders 3-4 in
numpy, marked 'cpu').

Ground truth (what 'err' columns measure against): the exact float64 integral over every texel of the same scene
rendered at --truth-face (default: the largest swept face, at least 256), after a power-preserving box downsample
to --truth-integrate texels per face (its loss against the undownsampled integral is measured once and printed).
For the shell scenes the analytic irradiance of their radiance function is a second reference ('err_analytic'
columns): closed form for 'sky', closed form + fine disc quadrature for 'sun', Gauss-Legendre for 'walls'. It also
measures the shell's own blur of the function, so it is reported, not used to rank.

Errors, per channel, over the irradiance cube's texel directions: rel RMS = sqrt(sum dOmega (a-t)^2 / sum dOmega t^2)
and max rel = max |a-t| / t; the 'rms'/'max' columns are the worst channel. Time = GPU timestamps of the render
('render_ms') plus the filter ('filter_ms', median of --repeats; wall time for numpy stages).
Outputs: DIR/accuracy_<device>.csv, DIR/accuracy_<device>.md, and the chart (default docs/accuracy-vs-speed.png).
Needs only numpy, matplotlib and the Vulkan binding (no plyfile/OpenImageIO/bpy).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import math
import os
import re
import statistics
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

from gs_ibl_addon.core import cubemap, synthetic  # noqa: E402
from gs_ibl_addon.core.probe import gpu_filters as gf  # noqa: E402
from gs_ibl_addon.core.probe.box import downsample_cube  # noqa: E402
from gs_ibl_addon.core.probe.reference import analytic_irradiance, exact_irradiance  # noqa: E402
from gs_ibl_addon.core.probe.sh_project import project_cube, sh_irradiance  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

T0 = time.perf_counter()
FILTER_REF_INTEGRATE = 64  # the per-cube reference integrates a <= 64^2 copy (loss ~2e-4 rel RMS, tests/test_probe_gpu)


def say(msg: str) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s] {msg}", flush=True)


# ------------------------------------------------------------------------------------------------------------
# Sweep definition

FULL = dict(faces=(16, 32, 64, 128, 256, 512, 1024), irr=(8, 16, 32), shell_splats=50_000,
            conv=((16, 4), (32, 8), (64, 16), (128, 32)), box=(1, 2, 4, "M"), exact=(8, 16, 32, 64),
            sh_cpu=(4, 6), sh_cpu_max_face=256, repeats=3)
QUICK = dict(faces=(16, 32, 64, 128), irr=(8, 16), shell_splats=20_000,
             conv=((16, 4), (32, 8), (64, 16)), box=(1, 2, "M"), exact=(8, 16, 32),
             sh_cpu=(4,), sh_cpu_max_face=128, repeats=1)


def configs(sw: dict, face: int, m: int) -> list[tuple[str, str, dict]]:
    """(method, label, parameters) for one face size and irradiance size. Odd SH orders above 1 are skipped: the
    clamped cosine has no odd band above 1 (A_3 = A_5 = 0), so order 3 gives order 2's irradiance at more cost."""
    out = [("sh", "sh2", {"order": 2})]
    if face <= sw["sh_cpu_max_face"]:
        out += [("sh", f"sh{o}", {"order": o}) for o in sw["sh_cpu"]]
    out += [("convolve", f"conv{p}x{t}", {"phi": p, "theta": t}) for p, t in sw["conv"]]
    levels = sorted({m if lv == "M" else lv for lv in sw["box"]})
    for lv in levels:
        if lv <= face and face % lv == 0 and ((face // lv) & (face // lv - 1)) == 0:
            out.append(("box", f"box{lv}" + ("=M" if lv == m else ""), {"level": lv}))
    seen = set()
    for d in sw["exact"]:
        k = gf.integration_size(face, d)
        if k not in seen:
            seen.add(k)
            out.append(("exact", f"exact{k}", {"downsample_to": d}))
    return out


# ------------------------------------------------------------------------------------------------------------
# Scenes and references

def sun_irradiance(sun: synthetic.BrightPatch, normals: np.ndarray, n_a: int = 48, n_phi: int = 192) -> np.ndarray:
    """E/pi of BrightPatch: the base gradient's closed form plus (disc - base) integrated over the disc by
    Gauss-Legendre in cos(angle from the disc centre) x uniform azimuth (the clamp at the horizon is applied per
    sample, so a disc cut by the horizon is handled)."""
    c = np.asarray(sun.direction, np.float64)
    c /= np.linalg.norm(c)
    x, wx = np.polynomial.legendre.leggauss(n_a)
    cmin = math.cos(math.radians(sun.radius_deg))
    mu = cmin + (x + 1.0) * 0.5 * (1.0 - cmin)
    wmu = wx * 0.5 * (1.0 - cmin)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    t = np.cross(c, [0.0, 0.0, 1.0] if abs(c[2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(c, t)
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - m * m)
    dirs = (m[..., None] * c + (s * np.cos(p))[..., None] * t + (s * np.sin(p))[..., None] * b).reshape(-1, 3)
    w = (wmu[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)).reshape(-1)
    excess = sun.disc_radiance[None] - sun.base(dirs)  # (S, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    disc = (np.maximum(nrm @ dirs.T, 0.0) * w) @ excess / np.pi
    return (sun.base.irradiance_over_pi(nrm) + disc).reshape(np.shape(normals)[:-1] + (3,))


def analytic_reference(name: str, fn, normals: np.ndarray) -> np.ndarray:
    if isinstance(fn, synthetic.SkyGradient):
        return fn.irradiance_over_pi(normals)
    if isinstance(fn, synthetic.BrightPatch):
        return sun_irradiance(fn, normals)
    return analytic_irradiance(fn, normals.reshape(-1, 3), 48, 96).reshape(normals.shape)


def build_scenes(sw: dict) -> list[tuple[str, object, np.ndarray, object]]:
    """(name, SplatScene, probe position, radiance function or None)."""
    out = []
    for name, fn in synthetic.radiance_functions().items():
        out.append((name, synthetic.shell_scene(fn, sw["shell_splats"]), np.zeros(3), fn))
    out.append(("room", synthetic.room_scene().scene, np.array([0.0, 0.0, 1.5]), None))
    out.append(("sample_env", synthetic.sample_environment(), np.array([0.0, 0.0, 1.0]), None))
    return out


def exact64(cube: np.ndarray, m: int, integrate: int) -> np.ndarray:
    rgb = np.asarray(cube[..., :3], np.float64) * 1.0  # alpha is coverage; RGB is premultiplied (holes black)
    while rgb.shape[1] > integrate and rgb.shape[1] % 2 == 0:
        rgb = downsample_cube(rgb)
    return exact_irradiance(rgb, cubemap.face_directions(m))


# ------------------------------------------------------------------------------------------------------------
# Errors

def errors(a: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel (rel RMS weighted by texel solid angle, max relative) of cube a against cube t."""
    w = cubemap.texel_solid_angles(a.shape[1])[None, :, :, None]
    rms = np.sqrt(np.sum(w * (a - t) ** 2, axis=(0, 1, 2)) / np.sum(w * t * t, axis=(0, 1, 2)))
    mx = np.max(np.abs(a - t) / np.maximum(np.abs(t), 1e-12), axis=(0, 1, 2))
    return rms, mx


# ------------------------------------------------------------------------------------------------------------
# Filters

def run_filter(method: str, p: dict, up: gf.GpuCube, cube: np.ndarray, m: int, repeats: int,
               sh_cache: dict) -> tuple[np.ndarray, float, str]:
    """(irradiance cube, filter ms, 'gpu'|'cpu'). SH projections are cached per cube (they do not depend on m),
    and their time is added to every evaluation from them."""
    def gpu(fn, *args):
        runs = [fn(*args) for _ in range(repeats)]
        return runs[-1][0], statistics.median(r[1].get("total", 0.0) for r in runs)

    if method == "sh" and p["order"] == 2:
        if "gpu" not in sh_cache:
            sh_cache["gpu"] = gpu(gf.gpu_sh_project, up)
        coeffs, t_proj = sh_cache["gpu"]
        irr, t = gpu(lambda c, s: gf.gpu_sh_irradiance(c, s, ctx=up.ctx), coeffs, m)
        return irr, t_proj + t, "gpu"
    if method == "sh":
        o = p["order"]
        if o not in sh_cache:
            t1 = time.perf_counter()
            sh_cache[o] = (project_cube(cube[..., :3], o), (time.perf_counter() - t1) * 1e3)
        coeffs, t_proj = sh_cache[o]
        t1 = time.perf_counter()
        irr = sh_irradiance(coeffs, cubemap.face_directions(m))
        return irr, t_proj + (time.perf_counter() - t1) * 1e3, "cpu"
    if method == "convolve":
        irr, t = gpu(gf.gpu_cosine_convolve, up, m, p["phi"], p["theta"])
    elif method == "box":
        irr, t = gpu(gf.gpu_box_irradiance, up, m, p["level"])
    else:
        irr, t = gpu(gf.gpu_exact_irradiance, up, m, p["downsample_to"])
    return irr, t, "gpu"


# ------------------------------------------------------------------------------------------------------------
# Reports

def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both time and error, sorted by time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def aggregate(rows: list[dict]) -> list[dict]:
    """One entry per (label, face, M): worst error over scenes, median time over scenes."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["label"], r["face"], r["irr"]), []).append(r)
    out = []
    for (label, face, m), rs in groups.items():
        worst = max(rs, key=lambda r: r["rms"])
        out.append({"label": label, "method": rs[0]["method"], "face": face, "irr": m, "where": rs[0]["filter_on"],
                    "rms": max(r["rms"] for r in rs), "max": max(r["max"] for r in rs), "worst_scene": worst["scene"],
                    "rms_filter": max(r["rms_filter"] for r in rs), "max_filter": max(r["max_filter"] for r in rs),
                    "time_ms": statistics.median(r["render_ms"] + r["filter_ms"] for r in rs),
                    "filter_ms": statistics.median(r["filter_ms"] for r in rs),
                    "render_ms": statistics.median(r["render_ms"] for r in rs),
                    "per_scene": {r["scene"]: r["rms"] for r in rs}})
    return out


def markdown(agg: list[dict], rows: list[dict], device: str, date: str, notes: list[str]) -> str:
    scenes = sorted({r["scene"] for r in rows}, key=lambda s: [r["scene"] for r in rows].index(s))
    lines = [f"# Probe irradiance accuracy vs speed: {device}, {date}", ""] + notes + [""]
    head = ("| irr M | method | face | where | time ms (render + filter) | filter ms | worst rel RMS | worst max rel | "
            + " | ".join(f"{s} RMS" for s in scenes) + " |")
    sep = "|" + "---|" * (8 + len(scenes))

    def row(a: dict) -> str:
        return (f"| {a['irr']} | {a['label']} | {a['face']} | {a['where']} | {a['time_ms']:.3f} | {a['filter_ms']:.3f} | "
                f"{a['rms']:.2%} | {a['max']:.2%} | " + " | ".join(f"{a['per_scene'].get(s, float('nan')):.2%}"
                                                                    for s in scenes) + " |")
    for m in sorted({a["irr"] for a in agg}):
        sub = [a for a in agg if a["irr"] == m]
        lines += [f"## Irradiance {m}x{m} per face", "", "Cheapest configuration within each tolerance "
                  "(worst rel RMS over all scenes), and the fastest of each method within it:", "", head, sep]
        for tol in (0.01, 0.05):
            ok = sorted((a for a in sub if a["rms"] <= tol), key=lambda a: a["time_ms"])
            lines.append(f"| **{tol:.0%}** | | | | | | | |" + " |" * len(scenes))
            picked = {}
            for a in ok:
                picked.setdefault(a["method"] + ("cpu" if a["where"] == "cpu" else ""), a)
            lines += [row(a) for a in sorted(picked.values(), key=lambda a: a["time_ms"])] or ["| none |"]
        lines += ["", "Pareto front (no configuration is both faster and more accurate):", "", head, sep]
        pts = [(a["time_ms"], a["rms"]) for a in sub]
        lines += [row(sub[i]) for i in pareto(pts)]
        lines.append("")
    # Per method at one middle configuration: where each fails.
    lines += ["## Per scene, every configuration at face 64 (or the largest swept), irradiance 16", "", head, sep]
    face = 64 if any(a["face"] == 64 for a in agg) else max(a["face"] for a in agg)
    m16 = 16 if any(a["irr"] == 16 for a in agg) else min(a["irr"] for a in agg)
    lines += [row(a) for a in sorted((a for a in agg if a["face"] == face and a["irr"] == m16),
                                     key=lambda a: a["time_ms"])]
    ana = [r for r in rows if r.get("rms_analytic") not in (None, "")]
    if ana:
        lines += ["", "## Shell scenes: exact filter against the analytic irradiance of the radiance function", "",
                  "(measures the renderer + shell representation, not the filter)", "",
                  "| scene | face | irr M | rel RMS vs analytic | max rel vs analytic | rel RMS vs ground truth |",
                  "|---|---|---|---|---|---|"]
        for r in ana:
            if r["method"] == "exact" and r["label"] == max((x["label"] for x in ana if x["method"] == "exact"
                                                             and x["face"] == r["face"]), key=lambda l: int(l[5:])):
                lines.append(f"| {r['scene']} | {r['face']} | {r['irr']} | {r['rms_analytic']:.2%} | "
                             f"{r['max_analytic']:.2%} | {r['rms']:.2%} |")
    return "\n".join(lines) + "\n"


COLOURS = {"sh2": "#1f77b4", "sh4": "#6baed6", "sh6": "#08306b", "convolve": "#d62728", "box": "#2ca02c",
           "exact": "#9467bd"}
MARKERS = {"sh": "o", "convolve": "^", "box": "s", "exact": "D"}


def family(a: dict) -> str:
    return a["label"] if a["method"] == "sh" else a["method"]


def chart(agg: list[dict], path: str, device: str, date: str) -> None:
    """Two panels at one irradiance size (16 if swept): left, what a probe costs against its error from the ground
    truth (render + filter); right, each filter alone on a given cube (filter time against the error from that
    cube's own exact integral). Points: every configuration (marker size = radiance face size); lines: each method's
    own best trade-off; black: the overall Pareto front, labelled."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = 16 if any(a["irr"] == 16 for a in agg) else min(a["irr"] for a in agg)
    sub = [a for a in agg if a["irr"] == m]
    faces = sorted({a["face"] for a in sub})
    size_of = {f: 12 + 80 * i / max(1, len(faces) - 1) for i, f in enumerate(faces)}
    fig, axes = plt.subplots(1, 2, figsize=(14, 6.2))
    panels = ((axes[0], "time_ms", "rms", "probe: render + filter vs ground truth",
               "GPU time per probe, ms (render + filter; median over scenes)"),
              (axes[1], "filter_ms", "rms_filter", "filter alone vs the exact integral of the same cube",
               "filter time, ms (GPU timestamps; numpy wall time for hollow markers)"))
    for ax, tk, ek, title, xlabel in panels:
        y = lambda a: max(a[ek], 1e-5)
        for fam, colour in COLOURS.items():
            pts = [a for a in sub if family(a) == fam]
            if not pts:
                continue
            cpu = pts[0]["where"] == "cpu"
            ax.scatter([a[tk] for a in pts], [y(a) for a in pts], s=[size_of[a["face"]] for a in pts],
                       marker=MARKERS[pts[0]["method"]], facecolors="none" if cpu else colour, edgecolors=colour,
                       alpha=0.55, linewidths=1.0, label=fam + (" (numpy)" if cpu else ""))
            own = [pts[i] for i in pareto([(a[tk], a[ek]) for a in pts])]
            ax.plot([a[tk] for a in own], [y(a) for a in own], "-", color=colour, lw=1.0, alpha=0.7)
        front = [sub[i] for i in pareto([(a[tk], a[ek]) for a in sub])]
        ax.plot([a[tk] for a in front], [y(a) for a in front], "k-", lw=2.0, alpha=0.35, label="Pareto front",
                zorder=3)
        last = math.inf
        for a in front:  # label the front where the error has moved visibly since the last label
            if y(a) < last / 1.6:
                ax.annotate(f"{a['label']}@{a['face']}", (a[tk], y(a)), fontsize=7, zorder=4, xytext=(5, -9),
                            textcoords="offset points")
                last = y(a)
        for tol, style in ((0.01, "--"), (0.05, ":")):
            ax.axhline(tol, color="0.25", ls=style, lw=1)
            ax.text(0.005, tol * 1.1, f"{tol:.0%} error", transform=ax.get_yaxis_transform(), fontsize=8,
                    color="0.25")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(title, fontsize=11)
        ax.set_xlabel(xlabel)
        ax.grid(True, which="major", alpha=0.3)
        ax.grid(True, which="minor", alpha=0.08)
    axes[0].set_ylabel(f"relative RMS error of {m}x{m} irradiance (worst channel, worst of {len(sub[0]['per_scene'])} scenes)")
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False,
               title=f"marker size = radiance face size ({faces[0]}..{faces[-1]}); thin lines: each method's best "
                     "trade-off; labels: configuration@face size", title_fontsize=8)
    fig.suptitle(f"Probe irradiance, accuracy vs speed: {device}, {date}", fontsize=12)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def replot(csv_path: str, out: str | None) -> None:
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k, v in r.items():
            if k not in ("device", "date", "scene", "method", "label", "params", "filter_on") and v != "":
                r[k] = float(v) if any(c in v for c in ".eE") or k.endswith("_ms") else int(v)
    device, date = rows[0]["device"], rows[0]["date"]
    slug = re.sub(r"[^a-z0-9]+", "-", device.lower()).strip("-")
    agg = aggregate(rows)
    folder = out or os.path.dirname(os.path.abspath(csv_path))
    png = os.path.join(folder, f"accuracy-vs-speed_{slug}.png")
    chart(agg, png, device, date)
    with open(os.path.join(folder, f"accuracy_{slug}.md"), "w", encoding="utf-8") as f:
        f.write(markdown(agg, rows, device, date, []))
    say(f"redrew {png}")


# ------------------------------------------------------------------------------------------------------------

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small sweep (~2-3 min on a 2-core lavapipe machine)")
    ap.add_argument("--out", default=None, help="folder for the CSV, markdown and chart (default: docs/bench for "
                                                "the tables, docs/accuracy-vs-speed.png for the chart)")
    ap.add_argument("--repeats", type=int, default=None, help="GPU filter runs per configuration (median)")
    ap.add_argument("--faces", default=None, help="comma-separated radiance face sizes (overrides the sweep)")
    ap.add_argument("--truth-face", type=int, default=None, help="face size of the ground-truth render")
    ap.add_argument("--truth-integrate", type=int, default=128, help="ground truth: integrate at this face size")
    ap.add_argument("--replot", default=None, metavar="CSV", help="redraw the chart and markdown from a CSV of this "
                                                                  "script (no rendering), into --out or next to it")
    args = ap.parse_args()
    if args.replot:
        replot(args.replot, args.out)
        return
    sw = dict(QUICK if args.quick else FULL)
    if args.faces:
        sw["faces"] = tuple(int(x) for x in args.faces.split(","))
    repeats = args.repeats or sw["repeats"]
    truth_face = args.truth_face or max(256, max(sw["faces"]))
    ctx = get_context()
    device = ctx.device_name
    slug = re.sub(r"[^a-z0-9]+", "-", device.lower()).strip("-")
    date = datetime.date.today().isoformat()
    out_dir = args.out or os.path.join(ROOT, "docs", "bench")
    png = os.path.join(args.out, f"accuracy-vs-speed_{slug}.png") if args.out else os.path.join(ROOT, "docs",
                                                                                               "accuracy-vs-speed.png")
    os.makedirs(out_dir, exist_ok=True)
    say(f"device {device}; faces {sw['faces']}, irradiance {sw['irr']}, truth face {truth_face} integrated at "
        f"{args.truth_integrate}, repeats {repeats}{' (quick)' if args.quick else ''}")
    rows: list[dict] = []
    notes: list[str] = []
    for name, scene, pos, fn in build_scenes(sw):
        say(f"scene {name}: {scene.count:,} splats, probe at {pos.tolist()}")
        r = SplatRenderer(scene, ctx)
        faces_needed = sorted(set(sw["faces"]) | {truth_face})
        cubes = {}
        for face in faces_needed:
            batch = ViewBatch.cubemap(pos, face)
            r.render(batch)  # warm-up: buffers sized, caches hot
            res = r.render(batch, timestamps=True)
            cubes[face] = (np.stack(res.images), res.timings_ms.get("total", res.wall_ms))
        r.close()
        truth_cube = cubes[truth_face][0]
        t1 = time.perf_counter()
        truth = {m: exact64(truth_cube, m, args.truth_integrate) for m in sw["irr"]}
        hole = float(1.0 - np.min(truth_cube[..., 3]))
        say(f"  rendered {faces_needed} ({', '.join(f'{f}: {cubes[f][1]:.2f} ms' for f in faces_needed)}); "
            f"ground truth {time.perf_counter() - t1:.1f} s")
        if name == "sun" and truth_face > args.truth_integrate:
            # What the ground truth's own downsampling costs, measured against twice the integration size.
            finer = exact64(truth_cube, 16, min(truth_face, 2 * args.truth_integrate))
            e = errors(exact64(truth_cube, 16, args.truth_integrate), finer)
            notes.append(f"Ground truth: {truth_face}^2-face render, box-downsampled to {args.truth_integrate}^2 and "
                         f"integrated in float64; downsampling loss on 'sun' against {min(truth_face, 2 * args.truth_integrate)}^2: "
                         f"rel RMS {e[0].max():.1e}, max rel {e[1].max():.1e}.")
            say("  " + notes[-1])
        ana = None
        if fn is not None:
            ana = {m: analytic_reference(name, fn, cubemap.face_directions(m)) for m in sw["irr"]}
            e = errors(truth[max(sw['irr'])], ana[max(sw['irr'])])
            say(f"  ground truth vs analytic irradiance: rel RMS {e[0].max():.2e}, max rel {e[1].max():.2e}")
        for face in sw["faces"]:
            cube, render_ms = cubes[face]
            up = gf.upload_cube(cube, ctx)
            sh_cache: dict = {}
            t1 = time.perf_counter()
            for m in sw["irr"]:
                own = exact64(cube, m, FILTER_REF_INTEGRATE)  # this very cube's integral: the filter's own error
                for method, label, p in configs(sw, face, m):
                    irr, filt_ms, where = run_filter(method, p, up, cube, m, repeats, sh_cache)
                    rms, mx = errors(irr, truth[m])
                    rf, mf = errors(irr, own)
                    row = {"device": device, "date": date, "scene": name, "splats": scene.count, "face": face,
                           "irr": m, "method": method, "label": label, "params": " ".join(f"{k}={v}" for k, v in p.items()),
                           "filter_on": where, "render_ms": round(render_ms, 4), "filter_ms": round(filt_ms, 4),
                           "time_ms": round(render_ms + filt_ms, 4), "rms": float(rms.max()), "max": float(mx.max()),
                           **{f"rms_{c}": float(v) for c, v in zip("rgb", rms)},
                           **{f"max_{c}": float(v) for c, v in zip("rgb", mx)},
                           "rms_filter": float(rf.max()), "max_filter": float(mf.max()),
                           "rms_analytic": "", "max_analytic": "", "hole_alpha": round(hole, 4)}
                    if ana is not None:
                        ra, ma = errors(irr, ana[m])
                        row["rms_analytic"], row["max_analytic"] = float(ra.max()), float(ma.max())
                    rows.append(row)
            up.close()
            best = min((x for x in rows if x["scene"] == name and x["face"] == face), key=lambda x: x["rms"])
            say(f"  face {face}: render {render_ms:.2f} ms, {sum(1 for x in rows if x['scene'] == name and x['face'] == face)}"
                f" configs in {time.perf_counter() - t1:.1f} s; best {best['label']} M={best['irr']} rms {best['rms']:.2e}")
    csv_path = os.path.join(out_dir, f"accuracy_{slug}.csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    agg = aggregate(rows)
    md = markdown(agg, rows, device, date, notes)
    md_path = os.path.join(out_dir, f"accuracy_{slug}.md")
    with open(md_path, "w", encoding="utf-8") as f:
        f.write(md)
    chart(agg, png, device, date)
    print(md)
    say(f"wrote {csv_path}, {md_path}, {png}")


if __name__ == "__main__":
    main()
