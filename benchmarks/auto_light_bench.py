"""Lighting "Auto" against native Cycles at five places in the sample room (issue 22, goal 2).

Target: white spheres and Suzannes at five places (centre, by the window, far corner, on the table, near the lamp)
within 3% of the mean of native Cycles at 8,192 spp (denoiser off), in Cycles and in EEVEE.

Run:  .venv/bin/python benchmarks/auto_light_bench.py [--native-samples 8192] [--samples 256] [--eevee-samples 16]
      [--places centre,window] [--meshes sphere] [--steps native,world,auto,volume]  (without native: the last
      run's) [--volume-budget 64 --volume-face 16]  (a trial of Lighting Volume's size)
      .venv/bin/python benchmarks/auto_light_bench.py --replot build/auto-light/run   (tables and chart again)
      .venv/bin/python benchmarks/auto_light_bench.py --animate window,lamp [--frames 48 --at 1,12,24,36,48]
      (issue 37's animation: both meshes move from the window to below the lamp, one Lighting Volume bake at frame
      1 for the whole range; native Cycles, 2,048 spp, and ours at the --at frames, each mesh alone from a camera
      moving with them; docs/bench/volume_animation.csv, docs/img/volume_animation.png)
Needs the trixie root (scripts/blender_roots.sh ensure trixie). The Blender side is benchmarks/auto_light_scene.py,
run in bpy 5.3 with the built zip installed by Blender's own installer through tests/real_blender/test_matrix.py's
machinery (built_zip, Runner, run_script), with the scene and set-up of tests/real_blender/blender_scene.py.
Writes docs/auto_light.csv, docs/img/auto_light.png (the chart) and docs/img/auto_light_renders.png (every render),
keeps the renders (.npy) and the result in build/auto-light/run (a --no-write trial in build/auto-light/run-trial,
its references taken from run), and prints a markdown table. A full run took 36 min
on a loaded 2-core machine (the ten 8,192-spp references 15).

The room (samples/room.ply, its colours re-encoded for Blender's sRGB rule) is imported by Blender's PLY importer
as native splats, hidden from the camera. Each mesh is rendered alone from its own camera (40x40, 40 degrees):
native Cycles lit only by the splats (World black, denoiser off) is the reference; ours is the probe at the room's
centre with the panel's defaults, Lighting World Probe, then Lighting Auto, each in Cycles and EEVEE. The number
per cell: the mean over the mesh's pixels (alpha > 0.999 in every render, so EEVEE's 1.5-pixel film filter and the
outline's partial pixels stay out, and one pixel in from that outline), per channel, ours over native. A cell is
within the target when all three channels are within 3%.
"""
from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "real_blender"))
import blender_scene as bs  # noqa: E402
from blender_scene import mesh_mask  # noqa: E402

RESULT_TAG = "GSIBL-AUTO-BENCH"
WORK = REPO / "build" / "auto-light"
CSV = REPO / "docs" / "auto_light.csv"
PNG = REPO / "docs" / "img" / "auto_light.png"
RENDERS = REPO / "docs" / "img" / "auto_light_renders.png"
ANIM_CSV = REPO / "docs" / "bench" / "volume_animation.csv"  # --animate (issue 37's animation target)
ANIM_PNG = REPO / "docs" / "img" / "volume_animation.png"
TOL = 0.03

# samples/room.ply (core/synthetic.py sample_environment): 6 x 5 x 3 m centred on the origin, floor z = 0, window
# in the +X wall (y -1.2..1.2, z 0.9..2.3) with daylight behind it, lamp at (0, 0, 2.75) (radius 0.12), table top
# x -1.5..-0.3, y -1.2..-0.2, z 0.70..0.76 with a yellow sphere (r 0.22) at (-1.0, -0.7, 0.98), pillar in the
# +X +Y corner. Each place: the mesh's centre and its camera (about 1.1 m away, looking at it).
PLACES = {
    "centre": {"centre": [0.0, 0.0, 1.2], "camera": [0.5, -0.9, 1.35]},
    "window": {"centre": [2.4, 0.0, 1.6], "camera": [1.7, -0.9, 1.7]},  # 0.6 m from the window's wall
    "corner": {"centre": [-2.3, 1.85, 0.8], "camera": [-1.6, 1.05, 1.0]},  # far from the window and the pillar
    "table": {"centre": [-0.5, -0.45, 1.01], "camera": [0.3, 0.3, 1.35], "rest_on": 0.76},  # on the table top
    "lamp": {"centre": [0.0, 0.0, 2.25], "camera": [0.4, -0.9, 2.15]},  # 0.5 m below the lamp
}
MESHES = ("sphere", "suzanne")
ENGINES = ("cycles", "eevee")
LIGHTS = ("auto", "world", "volume")  # Lighting Auto, World Probe, Volume (issue 37; --steps ...,volume)
PROBE = [0.0, 0.0, 1.2]


def cells(arrays: dict, result: dict, places, meshes) -> list[dict]:
    rows = []
    for place in places:
        for mesh in meshes:
            key = f"{mesh}_{place}"
            native = arrays.get(f"native_{key}")
            if native is None:
                continue
            for engine in ENGINES:
                for light in LIGHTS:
                    got = arrays.get(f"{light}_{engine}_{key}")
                    if got is None:
                        continue
                    mask = mesh_mask(native, got)
                    ratio = got[mask][:, :3].astype(np.float64).mean(0) / native[mask][:, :3].astype(np.float64).mean(0)
                    rows.append({"place": place, "mesh": mesh, "engine": engine, "lighting": light,
                                 "ratio_r": round(float(ratio[0]), 4), "ratio_g": round(float(ratio[1]), 4),
                                 "ratio_b": round(float(ratio[2]), 4), "ratio_mean": round(float(ratio.mean()), 4),
                                 "worst_off": round(float(np.abs(ratio - 1).max()), 4),
                                 "within_3pct": bool(np.abs(ratio - 1).max() <= TOL),
                                 "auto_choice": result.get("choice", {}).get(key, ""),
                                 "pixels": int(mask.sum()),
                                 "native_mean": round(float(native[mask][:, :3].mean()), 5),
                                 "render_s": round(result["times"].get(f"{light}_{engine}_{key}", 0.0), 2),
                                 "native_s": round(result["times"].get(f"native_{key}", 0.0), 1)})
    return rows


def plot(rows: list[dict], path: Path, title: str, keys=PLACES, ylim=(0.42, 1.85),
         ticks=(0.5, 0.6, 0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 1.75)) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.6), sharex=True)
    groups = [(p, m) for p in keys for m in MESHES]
    x = np.arange(len(groups))
    for ax, engine in zip(axes, ENGINES):
        ax.axhspan(1 - TOL, 1 + TOL, color="tab:green", alpha=0.18, lw=0, label="±3%")
        ax.axhline(1.0, color="k", lw=0.6)
        for dx, light, colour in ((-0.26, "auto", "tab:blue"), (0.0, "volume", "tab:orange"),
                                  (0.26, "world", "tab:gray")):
            vals, lo, hi = [], [], []
            for p, m in groups:
                r = next((r for r in rows if (r["place"], r["mesh"], r["engine"], r["lighting"]) ==
                          (p, m, engine, light)), None)
                ch = [r["ratio_r"], r["ratio_g"], r["ratio_b"]] if r else [np.nan] * 3
                vals.append(np.mean(ch))
                lo.append(np.mean(ch) - min(ch))
                hi.append(max(ch) - np.mean(ch))
            if not np.isfinite(vals).any():
                continue
            ax.bar(x + dx, np.asarray(vals) - 1.0, 0.25, bottom=1.0, color=colour, yerr=[lo, hi], capsize=2,
                   error_kw={"lw": 0.8}, label={"auto": "Lighting Auto", "world": "World Probe (one probe)",
                                                     "volume": "Lighting Volume"}[light])
            for xi, v in zip(x + dx, vals):
                if np.isfinite(v):
                    ax.annotate(f"{v:.2f}", (xi, v), textcoords="offset points", xytext=(0, 3 if v >= 1 else -9),
                                ha="center", fontsize=6.5, color=colour)
        ax.set_yscale("log")
        ax.set_ylim(*ylim)
        ax.set_yticks(ticks)
        ax.set_yticklabels([f"{t:g}" for t in ticks])
        ax.minorticks_off()
        ax.set_ylabel(f"{'Cycles' if engine == 'cycles' else 'EEVEE'}: ours / native")
        ax.grid(True, axis="y", alpha=0.3)
        for i in range(1, len(keys)):
            ax.axvline(2 * i - 0.5, color="k", lw=0.4, alpha=0.4)
    axes[0].legend(fontsize=7, loc="upper left", ncol=3)
    axes[1].set_xticks(x)
    axes[1].set_xticklabels([f"{p}\n{m}" for p, m in groups], fontsize=8)
    axes[0].set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def montage(run: Path, places, meshes, path: Path) -> None:
    """Every render of the run, each row one mesh at one place: native Cycles, World Probe, Auto and Volume (where
    run) in Cycles, the same in EEVEE; each row exposed so its native mean is 0.4."""
    from gs_ibl_addon.core.image_io import write_png_preview
    rows = []
    for place in places:
        for mesh in meshes:
            key = f"{mesh}_{place}"
            names = [f"{t}_{key}" for t in ("native", "world_cycles", "auto_cycles", "volume_cycles", "world_eevee",
                                             "auto_eevee", "volume_eevee")]
            names = [n for n in names if not n.startswith("volume") or (run / f"{n}.npy").exists()]
            if not all((run / f"{n}.npy").exists() for n in names):
                continue
            ims = [np.load(run / f"{n}.npy") for n in names]
            scale = 0.4 / max(float(ims[0][..., :3][ims[0][..., 3] > 0.999].mean()), 1e-6)
            rows.append(np.concatenate([np.pad(i[..., :3] * scale, ((1, 1), (1, 1), (0, 0)), constant_values=1)
                                        for i in ims], 1))
    if rows:
        half = (len(rows) + 1) // 2
        left, right = rows[:half], rows[half:] + [np.ones_like(rows[0])] * (2 * half - len(rows))
        img = np.concatenate([np.concatenate(left, 0), np.ones((len(left) * rows[0].shape[0], 6, 3)),
                              np.concatenate(right, 0)], 1)
        write_png_preview(path, np.repeat(np.repeat(img, 3, 0), 3, 1))


def report(rows: list[dict], result: dict, args: dict) -> str:
    t = result["times"]
    lines = [f"Blender {result['blender']}; native {args['native_samples']} spp, ours Cycles {args['samples']} spp, "
             f"EEVEE {args['eevee_samples']} samples; {args['size']}x{args['size']}",
             f"bakes: World Probe {t.get('world_bake_s', 0):.1f} s (cold), Auto {t.get('auto_bake_s', 0):.1f} s, "
             f"World Probe again {t.get('world_rebake_warm_s', 0):.1f} s (warm); EEVEE first frame "
             f"{t.get('eevee_first_s', 0):.1f} s",
             f"World report: {result.get('world_report')}", f"Auto report: {result.get('auto_report')}",
             *[f"  {x}" for x in result.get("local_report", [])],
             f"after a World Probe re-bake, local light left on: {result.get('after_world_rebake')}",
             f"Volume bake {t.get('volume_bake_s', 0):.1f} s: {result.get('volume_report')}",
             *[f"  {x}" for x in result.get("volume_local_report", [])],
             "", "| place | mesh | Auto chose | Cycles Auto | Cycles Volume | Cycles World | EEVEE Auto | EEVEE Volume "
                 "| EEVEE World |",
             "|---|---|---|---|---|---|---|---|---|"]

    def cell(p, m, e, light):
        r = next((r for r in rows if (r["place"], r["mesh"], r["engine"], r["lighting"]) == (p, m, e, light)), None)
        if r is None:
            return "–"
        s = f"{r['ratio_r']:.3f} / {r['ratio_g']:.3f} / {r['ratio_b']:.3f}"
        return f"**{s}**" if light != "world" and r["within_3pct"] else s
    for p in args.get("keys", PLACES):
        for m in MESHES:
            choice = result.get("choice", {}).get(f"{m}_{p}", "")
            if any(r["place"] == p and r["mesh"] == m for r in rows):
                lines.append(f"| {p} | {m} | {choice} | " + " | ".join(cell(p, m, e, lt) for e in ENGINES
                                                                         for lt in ("auto", "volume", "world")) + " |")
    for light in ("auto", "volume"):
        for e in ENGINES:
            got = [r for r in rows if r["lighting"] == light and r["engine"] == e]
            if got:
                lines.append(f"{light} {e} within 3% (every channel): {sum(r['within_3pct'] for r in got)} of "
                             f"{len(got)} cells")
    return "\n".join(lines)


def _options(text: str) -> dict:
    """"KEY=VALUE,..." -> {KEY: value}: values as JSON (True/False as Python writes them), else as text (CPU)."""
    def value(v: str):
        try:
            return json.loads(v.lower() if v in ("True", "False") else v)
        except ValueError:
            return v
    return {k: value(v) for k, v in (kv.split("=", 1) for kv in text.split(",") if kv)}


def _kept_natives(run: Path, args: dict) -> dict:
    """A run without the "native" step keeps the last run's references (their renders and times), when that run
    rendered them alike (same samples, size, meshes' albedo and places; main() checks the Blender); else none, and
    its cells are left out."""
    try:
        prev_args = json.loads((run / "args.json").read_text())
        prev = json.loads((run / "result.json").read_text())
    except (OSError, ValueError):
        return {}
    same = (all(prev_args.get(k) == args[k]
                for k in ("native_samples", "size", "radius", "suzanne_size", "fov_deg", "albedo"))
            and prev_args.get("cycles_settings", {}) == args["cycles_settings"])
    if not same:
        return {}
    if prev_args.get("animation") != args.get("animation"):
        return {}
    keys = {f"native_{m}_{p}" for m in args["meshes"] for p in args.get("keys", args["places"])
            if args.get("animation") or prev_args.get("places", {}).get(p) == args["places"][p]}
    return {"files": {f"{k}.npy": (run / f"{k}.npy").read_bytes() for k in keys if (run / f"{k}.npy").exists()},
            "times": {k: v for k, v in prev.get("times", {}).items() if k in keys}, "blender": prev.get("blender")}


def _write_animation(rows: list[dict], result: dict, args: dict) -> None:
    """The animation's CSV and chart (ANIM_CSV, ANIM_PNG): per frame and mesh, ours / native in both engines."""
    anim, date = args["animation"], args.get("date", time.strftime("%Y-%m-%d"))
    meta = {"date": date, "blender": result["blender"], "size": args["size"], "native_spp": args["native_samples"],
            "cycles_spp": args["samples"], "eevee_samples": args["eevee_samples"], "from": anim["from"],
            "to": anim["to"], "frames": anim["frames"]}
    with open(ANIM_CSV, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[*meta, *rows[0]])
        w.writeheader()
        for r in rows:
            w.writerow({**meta, **r})
    t = result["times"]
    plot(rows, ANIM_PNG, f"A white sphere and a Suzanne moving from the {anim['from']} to the {anim['to']} over "
                         f"{anim['frames']} frames, one Lighting Volume bake ({t.get('volume_bake_s', 0):.0f} s)\n"
                         f"mean of ours / native Cycles {args['native_samples']} spp at frames "
                         f"{', '.join(map(str, anim['at']))}, per-channel range as ticks\nours: Cycles "
                         f"{args['samples']} spp, EEVEE {args['eevee_samples']} samples; Blender {result['blender']}, "
                         f"2-core CPU, {date}", keys=args["keys"], ylim=(0.86, 1.2),
         ticks=(0.9, 0.95, 0.97, 1.0, 1.03, 1.05, 1.1, 1.15))
    print(f"\n{ANIM_CSV}\n{ANIM_PNG}")


def _finish(run: Path, write: bool) -> None:
    result = json.loads((run / "result.json").read_text())
    args = json.loads((run / "args.json").read_text())
    arrays = {p.stem: np.load(p) for p in run.glob("*.npy")}
    keys = args.get("keys", args["places"])
    rows = cells(arrays, result, keys, args["meshes"])
    text = report(rows, result, args)
    print(text)
    (run / "report.md").write_text(text + "\n")
    if write and rows and args.get("animation"):
        _write_animation(rows, result, args)
    elif write and rows:
        date = args.get("date", time.strftime("%Y-%m-%d"))
        meta = {"date": date, "blender": result["blender"], "size": args["size"],
                "native_spp": args["native_samples"], "cycles_spp": args["samples"],
                "eevee_samples": args["eevee_samples"]}
        CSV.parent.mkdir(parents=True, exist_ok=True)
        with open(CSV, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=[*meta, *rows[0]])
            w.writeheader()
            for r in rows:
                w.writerow({**meta, **r})
        PNG.parent.mkdir(parents=True, exist_ok=True)
        t = result["times"]
        plot(rows, PNG, f"White sphere and Suzanne (albedo 0.8) at five places in the sample room: mean of ours / "
                        f"native Cycles {args['native_samples']} spp (denoiser off), per-channel range as ticks\n"
                        f"probe at the room's centre, panel defaults; ours: Cycles {args['samples']} spp, EEVEE "
                        f"{args['eevee_samples']} samples; Blender {result['blender']}, 2-core CPU, {date}\n"
                        "whole bakes: "
                        f"World {t.get('world_bake_s', 0):.0f} s, Auto {t.get('auto_bake_s', 0):.0f} s, Volume "
                        f"{t.get('volume_bake_s', 0):.0f} s")
        montage(run, args["places"], args["meshes"], RENDERS)
        print(f"\n{CSV}\n{PNG}\n{RENDERS}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--native-samples", type=int, default=None, help="8,192 (2,048 with --animate)")
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--eevee-samples", type=int, default=16)
    ap.add_argument("--size", type=int, default=40)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--places", default=",".join(PLACES))
    ap.add_argument("--meshes", default=",".join(MESHES))
    ap.add_argument("--steps", default=None, help="native,world,auto (native,volume with --animate)")
    ap.add_argument("--eevee-set", default="", metavar="KEY=VALUE,...",
                    help="EEVEE options for a trial (scene.eevee, e.g. use_fast_gi=False,clamp_surface_indirect=0)")
    ap.add_argument("--cycles-set", default="", metavar="KEY=VALUE,...",
                    help="Cycles options for a trial, every render (scene.cycles, e.g. diffuse_bounces=0)")
    ap.add_argument("--volume-budget", type=int, default=None, help="Lighting Volume's probe budget (a trial)")
    ap.add_argument("--volume-face", type=int, default=None, help="Lighting Volume's cube face (a trial)")
    ap.add_argument("--animate", metavar="FROM,TO", default=None,
                    help="issue 37's animation: the meshes move from one place to another (e.g. window,lamp) over "
                         "--frames, one Lighting Volume bake, native and ours at --at frames (steps default "
                         "native,volume; native 2,048 spp unless given)")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--at", default="1,12,24,36,48", help="the frames rendered in an animation")
    ap.add_argument("--no-write", action="store_true", help="leave docs/ alone (a trial run)")
    ap.add_argument("--replot", metavar="RUN", help="tables, CSV and chart again from a kept run folder")
    a = ap.parse_args()
    if a.replot:
        _finish(Path(a.replot), not a.no_write)
        return
    import test_matrix as matrix
    matrix.TIMEOUT_S = 4 * 3600  # the matrix's per-command limit is for tests
    matrix.OUT = WORK  # built_zip() builds into a folder of ours, not the matrix's
    entry = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
    try:
        matrix.require_root(entry.root)
    except BaseException as e:  # pytest's skip outside pytest
        sys.exit(f"the bpy 5.3 root is not ready: {e}")
    unknown = [p for p in a.places.split(",") if p not in PLACES]
    if unknown:  # before the runner: a failed run replaces the last run's folder (and its references)
        sys.exit(f"unknown --places {','.join(unknown)}: choose from {','.join(PLACES)}")
    anim = None
    if a.animate:
        ends = a.animate.split(",")
        if len(ends) != 2 or any(p not in PLACES for p in ends):
            sys.exit(f"--animate {a.animate}: two of {','.join(PLACES)}, FROM,TO")
        at = sorted({int(x) for x in a.at.split(",")})
        if at[0] < 1 or at[-1] > a.frames:
            sys.exit(f"--at {a.at}: frames from 1 to --frames {a.frames}")
        anim = {"from": ends[0], "to": ends[1], "frames": a.frames, "at": at}
        a.places = a.animate
    native_samples = a.native_samples or (2048 if anim else 8192)
    steps = (a.steps or ("native,volume" if anim else "native,world,auto")).split(",")
    places = {p: PLACES[p] for p in a.places.split(",")}
    t_start = time.perf_counter()
    runner = matrix.Runner(entry, None)
    # a trial (--no-write) keeps its renders apart: the kept run's references stay whole for the next full run
    kept_run = WORK / ("animation" if anim else "run")
    run = kept_run.with_name(kept_run.name + "-trial") if a.no_write else kept_run
    result: dict = {}
    kept: dict = {}
    try:
        room = bs.write_room_for_blender(runner.host / "room.ply", REPO / "samples" / "room.ply")
        args = {"work": str(runner.inner), "ply": str(runner.inner / "room.ply"), "size": a.size, "albedo": 0.8,
                "radius": 0.25, "suzanne_size": 0.4, "fov_deg": 40.0, "places": places,
                "meshes": a.meshes.split(","), "probe": PROBE, "native_samples": native_samples,
                "samples": a.samples, "eevee_samples": a.eevee_samples, "threads": a.threads,
                "steps": steps, "date": time.strftime("%Y-%m-%d"), "animation": anim,
                "keys": [f"f{f:02d}" for f in anim["at"]] if anim else list(places),
                "eevee_settings": _options(a.eevee_set), "cycles_settings": _options(a.cycles_set),
                "volume_budget": a.volume_budget, "volume_face": a.volume_face}
        kept = _kept_natives(kept_run, args) if "native" not in args["steps"] else {}
        result = matrix.run_script(runner, HERE / "auto_light_scene.py", args, RESULT_TAG, "auto")
        result["wall_s"] = time.perf_counter() - t_start
        head = np.asarray(result.get("positions_head", []))
        if len(head):  # Blender's importer put the splats where our reader does: the places are where meant
            result["positions_max_diff"] = float(np.abs(head - room.positions[:len(head)]).max())
    finally:
        shutil.rmtree(run, ignore_errors=True)
        shutil.copytree(runner.host, run, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip", "*.blend*"))
        runner.close()
        if kept and kept.get("blender") == result.get("blender"):  # references from another Blender: none
            for name, data in kept["files"].items():
                (run / name).write_bytes(data)
            result["times"] = {**kept["times"], **result.get("times", {})}
    (run / "result.json").write_text(json.dumps(result, indent=1))
    (run / "args.json").write_text(json.dumps(args, indent=1))
    if not result.get("ok"):
        sys.exit(f"the Blender side failed:\n{result.get('error')}")
    print(f"wall {result['wall_s']:.0f} s; splat positions vs our reader: {result.get('positions_max_diff')}")
    _finish(run, not a.no_write)


if __name__ == "__main__":
    main()
