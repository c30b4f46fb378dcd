"""Check bake.py's face-size search against the ground truth: what the search sees, what the error is, what it costs.

Run: python benchmarks/trials/auto_search_check.py [--quick] [--max-face 512] [--out CSV]

For each scene of benchmarks/accuracy_bench.py's sweep (its full sweep's scenes, or --quick's 20k-splat shells), one
probe is baked at every face size 32, 64, ... --max-face exactly as bake_probe's search bakes its steps
(``bake_probe(face_size=N)``: method auto = exact on the GPU, downsample to 32, irradiance 16^2). Per scene and face:

- ``change``: what the search tests, ``bake.relative_rms(irradiance at N/2, irradiance at N)`` (all channels and
  texels pooled, unweighted), N >= 64.
- ``err_pooled``: the same statistic against the ground truth, ``bake.relative_rms(irradiance at N, truth)``;
  ``err_worst_channel`` / ``max_rel_worst_channel``: accuracy_bench's errors (per channel, rel RMS weighted by texel
  solid angle and max relative; the worst channel), the numbers of docs/accuracy.md's other tables.
- Ground truth as in accuracy_bench: the scene rendered at --truth-face (1024^2), box-downsampled to
  --truth-integrate (128^2) and integrated exactly in float64 (accuracy_bench.exact64). When --max-face equals the
  truth face, the truth reuses that step's render.
- GPU time of each step from timestamps: ``render_ms`` (whole cubemap) + ``sh_project_ms`` (bake_probe always
  stores the 9 SH coefficients) + ``irradiance_ms`` (the exact filter) = ``step_gpu_ms``; ``step_wall_ms`` is
  bake_probe's own wall time for the step (upload, readbacks, host work included); ``cum_*`` add the steps from 32^2.
  Each face is baked --warmup times untimed, then --repeats times; the run with the median step_gpu_ms is reported
  (``load1``: the 1-minute load average then; on lavapipe the "GPU" is the CPU, shared with whatever else runs).
- For each --tolerances value T (columns ``auto_<T>``): "stops" on the face where bake_probe's rule (start at 32^2,
  double, stop when change <= T, keep the finer face; give up at --max-face) stops on these changes, "stops, not
  converged" where it gives up. Unless --no-verify, bake_probe(face_size=0, tolerance=T) itself is run too and
  ``bake_probe_<T>`` marks the face it returned, with its wall time: the replay and the real search must agree.

Writes one CSV (default out/bench/auto_search_<device>.csv) and prints a summary per tolerance: where the search
stops, the true error there, its GPU time, and the smallest face whose true error is within the tolerance.
Needs only numpy and the Vulkan binding (no plyfile/OpenImageIO/bpy).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import re
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # benchmarks/ (this file is in its trials/)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, ".."))

import accuracy_bench as ab  # noqa: E402
from gs_ibl_addon.core.bake import AUTO_FIRST_FACE, ProbeSettings, bake_probe, relative_rms  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

IRRADIANCE = ProbeSettings().irradiance_size  # what bake_probe bakes by default (16)


def tol_key(t: float) -> str:
    return f"{100 * t:g}pct"


def bake_step(r: SplatRenderer, scene, pos: np.ndarray, face: int, warmup: int, repeats: int):
    """One search step as bake_probe bakes it, and its times: the run with the median GPU time of ``repeats``."""
    settings = ProbeSettings(face_size=face)
    for _ in range(warmup):
        bake_probe(scene, pos, settings, renderer=r)
    runs = []
    for _ in range(repeats):
        p = bake_probe(scene, pos, settings, renderer=r)
        t = p.timings_ms
        times = {"render_ms": t.get("render_total", 0.0), "sh_project_ms": t.get("sh_project", 0.0),
                 "irradiance_ms": t.get("irradiance", 0.0)}
        times["step_gpu_ms"] = sum(times.values())
        times["step_wall_ms"] = t.get("bake_wall", 0.0)
        times["load1"] = os.getloadavg()[0]  # a CPU device (lavapipe) shares the cores with everything else
        runs.append((p, times))
    runs.sort(key=lambda pt: pt[1]["step_gpu_ms"])
    return runs[len(runs) // 2]


def replay(changes: dict[int, float], tol: float, max_face: int) -> tuple[int, bool]:
    """bake_probe's rule on measured changes: (face it ends at, converged)."""
    face = AUTO_FIRST_FACE
    while face < max_face:
        face *= 2
        if changes[face] <= tol:
            return face, True
    return face, False


def run_scene(name, scene, pos, ctx, args, faces, tolerances, device, date) -> list[dict]:
    r = SplatRenderer(scene, ctx)
    try:
        probes, times = {}, {}
        for face in faces:
            probes[face], times[face] = bake_step(r, scene, pos, face, args.warmup, args.repeats)
            ab.say(f"  {face}^2: render {times[face]['render_ms']:.2f} ms + SH {times[face]['sh_project_ms']:.2f} + "
                   f"exact {times[face]['irradiance_ms']:.2f} ms GPU; step wall {times[face]['step_wall_ms']:.0f} ms")
        t1 = time.perf_counter()
        if args.truth_face in probes:
            truth_cube = probes[args.truth_face].radiance
        else:
            truth_cube = np.stack(r.render(ViewBatch.cubemap(pos, args.truth_face)).images)
        truth = ab.exact64(truth_cube, IRRADIANCE, args.truth_integrate)
        ab.say(f"  ground truth ({args.truth_face}^2 -> {args.truth_integrate}^2, float64): "
               f"{time.perf_counter() - t1:.1f} s")
        verified: dict[float, tuple[int, float, list]] = {}
        if not args.no_verify:
            for tol in tolerances:
                p = bake_probe(scene, pos, ProbeSettings(face_size=0, tolerance=tol, max_face_size=args.max_face),
                               renderer=r)
                verified[tol] = (int(p.settings["face_size"]), p.timings_ms["bake_wall"],
                                 p.settings["face_size_trials"])
    finally:
        r.close()

    changes = {f: relative_rms(probes[f // 2].irradiance, probes[f].irradiance) for f in faces[1:]}
    stops = {tol: replay(changes, tol, args.max_face) for tol in tolerances}
    rows, cum_gpu, cum_wall = [], 0.0, 0.0
    for face in faces:
        irr = probes[face].irradiance
        rms, mx = ab.errors(irr, truth)
        cum_gpu += times[face]["step_gpu_ms"]
        cum_wall += times[face]["step_wall_ms"]
        row = {"device": device, "date": date, "scene": name, "splats": scene.count, "face": face,
               "irradiance": IRRADIANCE, "repeats": args.repeats, "truth_face": args.truth_face,
               "truth_integrate": args.truth_integrate,
               "change": changes.get(face, ""), "err_pooled": relative_rms(irr, truth),
               "err_worst_channel": float(rms.max()), "max_rel_worst_channel": float(mx.max()),
               **times[face], "cum_gpu_ms": cum_gpu, "cum_wall_ms": cum_wall}
        for tol in tolerances:
            end, converged = stops[tol]
            row[f"auto_{tol_key(tol)}"] = ("stops" if converged else "stops, not converged") if face == end else ""
            if verified:
                vface, vwall, _ = verified[tol]
                row[f"bake_probe_{tol_key(tol)}"] = "ends" if face == vface else ""
                row[f"bake_probe_wall_ms_{tol_key(tol)}"] = vwall if face == vface else ""
        rows.append(row)
    for tol, (vface, _, trials) in verified.items():
        end = stops[tol][0]
        seen = {t["face_size"]: t["change"] for t in trials if t["change"] is not None}
        worst = max((abs(seen[f] - changes[f]) / max(changes[f], 1e-12) for f in seen if f in changes), default=0.0)
        msg = (f"  tolerance {tol:g}: replay ends at {end}^2, bake_probe at {vface}^2; its changes differ from the "
               f"replay's by <= {worst:.1e} (relative)")
        ab.say(msg if vface == end else "MISMATCH" + msg)
    return rows


def summary(rows: list[dict], tolerances: list[float]) -> str:
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    lines = ["| scene | face | change from half face | true error (worst channel) | pooled | change / pooled error | "
             "step GPU ms | " + " | ".join(f"auto {t:g}" for t in tolerances) + " |",
             "|---|---|---|---|---|---|---|" + "---|" * len(tolerances)]
    for r in rows:
        ch = r["change"]
        ratio = f"{ch / r['err_pooled']:.2f}" if ch != "" and r["err_pooled"] > 0 else ""
        lines.append(f"| {r['scene']} | {r['face']} | {'' if ch == '' else f'{ch:.4%}'} | "
                     f"{r['err_worst_channel']:.4%} | {r['err_pooled']:.4%} | {ratio} | {r['step_gpu_ms']:.2f} | "
                     + " | ".join(r[f"auto_{tol_key(t)}"] for t in tolerances) + " |")
    lines += ["", "| tolerance | scene | search ends at | true error there | search GPU ms (all steps) | "
              "smallest face within tolerance | its error | its GPU ms | search / smallest |", "|---" * 9 + "|"]
    for t in tolerances:
        for s in scenes:
            rs = [r for r in rows if r["scene"] == s]
            end = next(r for r in rs if r[f"auto_{tol_key(t)}"])
            # the smallest face, not the fastest measured: on a shared CPU device the times are noisy
            cheap = next((r for r in rs if r["err_worst_channel"] <= t), None)
            lines.append(f"| {t:g} | {s} | {end['face']}{'' if end[f'auto_{tol_key(t)}'] == 'stops' else ' (not converged)'}"
                         f" | {end['err_worst_channel']:.4%} | {end['cum_gpu_ms']:.2f} | "
                         + (f"{cheap['face']} | {cheap['err_worst_channel']:.4%} | {cheap['step_gpu_ms']:.2f} | "
                            f"{end['cum_gpu_ms'] / cheap['step_gpu_ms']:.1f}x |" if cheap else "none | | | |"))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="accuracy_bench's --quick scenes (20k-splat shells)")
    ap.add_argument("--max-face", type=int, default=1024, help="largest face baked, and where the search gives up")
    ap.add_argument("--tolerances", default="0.05,0.01,0.001", help="comma-separated tolerances of the rule to replay")
    ap.add_argument("--truth-face", type=int, default=1024, help="face size of the ground-truth render")
    ap.add_argument("--truth-integrate", type=int, default=128, help="ground truth: integrate at this face size")
    ap.add_argument("--warmup", type=int, default=1, help="untimed bakes of each face before the timed ones")
    ap.add_argument("--repeats", type=int, default=1, help="timed bakes per face; the median one is reported")
    ap.add_argument("--no-verify", action="store_true", help="skip running bake_probe's real search per tolerance")
    ap.add_argument("--scenes", default=None, help="comma-separated scene names (default: all of the sweep)")
    ap.add_argument("--out", default=None, help="CSV path (default out/bench/auto_search_<device>.csv)")
    args = ap.parse_args()
    faces = []
    f = AUTO_FIRST_FACE
    while f <= args.max_face:
        faces.append(f)
        f *= 2
    if len(faces) < 2 or faces[-1] != args.max_face:
        ap.error(f"--max-face {args.max_face} must be {AUTO_FIRST_FACE} times a power of two, at least "
                 f"{2 * AUTO_FIRST_FACE}")
    tolerances = [float(x) for x in args.tolerances.split(",")]
    ctx = get_context()
    device = ctx.device_name
    slug = re.sub(r"[^a-z0-9]+", "-", device.lower()).strip("-")
    date = datetime.date.today().isoformat()
    out = args.out or os.path.join(HERE, "..", "out", "bench", f"auto_search_{slug}.csv")
    sw = ab.QUICK if args.quick else ab.FULL
    wanted = set(args.scenes.split(",")) if args.scenes else None
    ab.say(f"device {device}; faces {faces}; truth {args.truth_face}^2 integrated at {args.truth_integrate}^2; "
           f"tolerances {tolerances}; {'quick' if args.quick else 'full'} sweep's scenes")
    rows: list[dict] = []
    for name, scene, pos, _fn in ab.build_scenes(sw):
        if wanted and name not in wanted:
            continue
        ab.say(f"scene {name}: {scene.count:,} splats, probe at {pos.tolist()}")
        rows += run_scene(name, scene, pos, ctx, args, faces, tolerances, device, date)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    print(summary(rows, tolerances))
    ab.say(f"wrote {out}")


if __name__ == "__main__":
    main()
