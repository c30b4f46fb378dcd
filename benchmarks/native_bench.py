"""Speed against Blender's native splats at users' working points (issue 16 part 5, issue 22 goal 3): time against
per-pixel error for a lit mesh in the sample room, Blender 5.3's Cycles path-tracing the native splats (denoiser off
and on) against our bake (Lighting Auto, the panel's defaults; then Lighting Volume on the same probe, issue 37,
unless --lighting auto) + Cycles and + EEVEE, for a 48x48, a 320x180 and a 960x540 frame and a 24-frame camera
move at 320x180 (baked once, rendered as one animation job with persistent data, native too). Same machine, same
run, one Blender (bpy 5.3 in the trixie root, with the built zip installed by Blender's own installer, as
tests/real_blender/ does). The GPU machine's Auto and Volume bakes of the same settings (benchmarks/auto_bake_core.py,
core, clock held; the newest rows of docs/bench/{auto,volume}_bake_core_nvidia-*.csv) are drawn as their own
series: that bake's time + our EEVEE render's time here.

Run:  python benchmarks/native_bench.py [--frames 48x48,320x180,960x540] [--no-move] [--quick] [--lighting auto]
      python benchmarks/native_bench.py --plot-only docs/bench/native_lavapipe.csv
Needs the trixie root (scripts/blender_roots.sh ensure trixie). Writes docs/bench/native_<device>.csv (+ .json:
references, bake report) and docs/native-vs-ours.png, and prints markdown tables: every point, then per frame our
fastest point and native's time to the same error.

The scene: samples/room.ply imported by our importer (on 5.3 a native Gaussian-splat Point Cloud), a white diffuse
sphere (albedo 0.8, radius 0.3 m; 33, 70 and 210 px wide in the three frames), the splats hidden from the camera
(film transparent) so every error is the sphere's light. Reference per frame: two native Cycles renders of
independent seeds inside the sphere's region (Render Region), denoiser off; a render's error is the RMS over the
sphere's pixels (one pixel in from the outline) of (render - their mean), less the mean's own noise (a quarter of
var(R1 - R2), which is independent of the render measured), over the mean's RMS, RGB pooled. The raw RMS is kept
too. The move's error pools its first and last frames, each against its own reference. Time: wall seconds of the
render call; ours adds the warm re-bake (the first bake of the session, Vulkan start included, is recorded).

Inside Blender this same file runs with --in-blender ARGS.json (tests/real_blender/blender_scene.py beside it).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, ".."))
# the scene and the Blender set-up: tests/real_blender/blender_scene.py here, copied beside this file in Blender
sys.path[:0] = [os.path.join(REPO, "tests", "real_blender"), HERE]
import blender_scene as bs  # noqa: E402
from blender_scene import MODULE, mesh_mask  # noqa: E402

RESULT_TAG = "GSIBL-NATIVE-BENCH "
VOLUME_LABEL = "our Volume bake"  # Lighting Volume's rows: "<label> + Cycles", "<label> + EEVEE"


# ---------------------------------------------------------------------------------------------------- in Blender

# name: (width, height, camera offset from the sphere (m), lens (mm)); the sphere is 33, 70 and 210 px wide
FRAMES = {"48x48": (48, 48, (0.0, -1.2, 0.25), 50.0),
          "320x180": (320, 180, (0.0, -1.86, 0.39), 25.0),
          "960x540": (960, 540, (0.0, -1.86, 0.39), 25.0)}
MOVE = {"frame": "320x180", "frames": 24, "turn_deg": 40.0}  # an orbit about the sphere, bake once


def _in_blender(args: dict) -> dict:
    import importlib
    import math

    import bpy
    import numpy as np
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Matrix, Vector

    bs.enable_extension()
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    bs.clear("objects")
    scene = bpy.context.scene
    bs.black_world()
    assert bpy.ops.gs_ibl.import_splats(filepath=args["room"]) == {"FINISHED"}
    room = bpy.context.active_object
    out = {"blender": bpy.app.version_string, "native": so.is_native_splats(room), "rows": [], "frames": {}}
    at = room.matrix_world @ Vector(args["probe_in_room"])
    radius = bs.ROOM_SPHERE["radius"]
    sphere = bs.sphere(at, radius, bs.white_material("White", bs.ALBEDO), segments=64, rings=32)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.threads_mode = "FIXED"
    r.threads = args["threads"]
    r.use_persistent_data = True  # the move renders as one job: each engine keeps its scene between frames
    room.visible_camera = False  # the sphere alone in the picture: every error is its light
    # Cycles' own path tracing of the native splats: Splats in Renders off (on, the Native Splats default, F12 draws
    # them with our renderer and hides them from Cycles; tests/real_blender/cycles_reference.py does the same)
    scene.gs_ibl_render.enabled = False
    r.film_transparent = True  # after: turning Splats in Renders off put back the Film Transparent import found (off)
    scene.view_settings.view_transform = "Standard"
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.transparent_max_bounces = 64
    eevee = bs.eevee_engine()
    work = args["work"]

    def place_camera(frame: str, turn: float = 0.0) -> None:
        w, h, offset, lens = FRAMES[frame]
        r.resolution_x, r.resolution_y = w, h
        cam.location = at + Matrix.Rotation(turn, 3, "Z") @ Vector(offset)
        cam.rotation_euler = (at - cam.location).to_track_quat("-Z", "Y").to_euler()
        cam.data.lens = lens

    def setup(engine: str, samples: int, denoise: bool = False, seed: int = 0) -> None:
        r.engine = engine
        if engine == "CYCLES":
            c.samples, c.use_denoising, c.seed = samples, denoise, seed
            if denoise:
                c.denoiser = "OPENIMAGEDENOISE"
        else:
            scene.eevee.taa_render_samples = samples

    def load(path: str) -> np.ndarray:
        return bs.read_image(path, top_first=False)

    def render(engine: str, samples: int, denoise: bool = False, seed: int = 0, border=None):
        setup(engine, samples, denoise, seed)
        r.use_border = border is not None
        if border is not None:
            r.use_crop_to_border = False
            r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = border
        path = os.path.join(work, "frame.exr")
        r.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - t0
        r.use_border = False
        return load(path), seconds

    def render_move(engine: str, samples: int, denoise: bool = False):
        """The 24-frame move as one animation job: (frame 1, frame 24), seconds for all."""
        setup(engine, samples, denoise)
        place_camera(MOVE["frame"])  # its resolution (the move's camera is keyed)
        r.filepath = os.path.join(work, "move_####")
        scene.frame_start, scene.frame_end = 1, MOVE["frames"]
        scene.camera = move_cam
        t0 = time.perf_counter()
        bpy.ops.render.render(animation=True)
        seconds = time.perf_counter() - t0
        scene.camera = cam
        return (load(os.path.join(work, "move_0001.exr")),
                load(os.path.join(work, f"move_{MOVE['frames']:04d}.exr"))), seconds

    def sphere_border() -> tuple:
        """The sphere's box in the frame, 4 px wider: the references render there alone (Render Region)."""
        pts = [world_to_camera_view(scene, scene.camera, sphere.matrix_world @ Vector(v)) for v in sphere.bound_box]
        mx, my = 4.0 / r.resolution_x, 4.0 / r.resolution_y
        return (max(0.0, min(p.x for p in pts) - mx), min(1.0, max(p.x for p in pts) + mx),
                max(0.0, min(p.y for p in pts) - my), min(1.0, max(p.y for p in pts) + my))

    class Reference:
        """Two native renders of independent seeds at ``samples``, inside the sphere's region. Errors are
        against their mean, less its own noise (var(R1 - R2) / 4 per pixel, independent of what is measured):
        err^2 = mean((X - Rm)^2) - var_pixel(Rm), over mean(Rm^2)."""

        def __init__(self, label: str, samples: int):
            border = sphere_border()
            (a, sa), (b, sb) = (render("CYCLES", samples, seed=s, border=border) for s in (101, 102))
            # one pixel in from the outline: edges are each engine's own filter
            self.mask = m = mesh_mask(a, b)
            region = (border[1] - border[0]) * r.resolution_x * (border[3] - border[2]) * r.resolution_y
            if m.sum() > 0.9 * region:  # a sphere fills pi/4 of its box: an opaque background (2026-12-05's runs)
                raise RuntimeError(f"{label}: the sphere's mask covers {int(m.sum())} of its region's {region:.0f} "
                                   "pixels: the references are opaque (Film Transparent off?)")
            self.a, self.b = a[m][:, :3].astype(np.float64), b[m][:, :3].astype(np.float64)
            self.mean = 0.5 * (self.a + self.b)
            self.noise_var = float(np.mean((self.a - self.b) ** 2)) / 4.0  # of the mean's pixels
            self.norm = float(np.mean(self.mean ** 2))
            out["frames"][label] = {"reference_samples": samples, "reference_s": round(sa + sb, 2),
                                    "sphere_pixels": int(m.sum()),
                                    "reference_noise": round((self.noise_var / self.norm) ** 0.5, 5),
                                    "border": [round(x, 4) for x in border]}
            print(label, out["frames"][label], flush=True)

        def error(self, px) -> tuple[float, float]:
            d2 = float(np.mean((px[self.mask][:, :3].astype(np.float64) - self.mean) ** 2))
            return max(d2 - self.noise_var, 0.0) ** 0.5 / self.norm ** 0.5, (d2 / self.norm) ** 0.5

        def ratio(self, px) -> float:
            return float(px[self.mask][:, :3].mean() / self.mean.mean())

    def row(frame: str, ref, method: str, samples: int, render_s: float, px, bake_s: float = 0.0, refs=None):
        errs = [ref.error(px)] if refs is None else [rf.error(p) for rf, p in zip(refs, px)]
        e = float(np.sqrt(np.mean([x[0] ** 2 for x in errs])))
        raw = float(np.sqrt(np.mean([x[1] ** 2 for x in errs])))
        ratio = ref.ratio(px) if refs is None else float(np.mean([rf.ratio(p) for rf, p in zip(refs, px)]))
        out["rows"].append({"frame": frame, "method": method, "samples": samples, "render_s": round(render_s, 3),
                            "bake_s": round(bake_s, 3), "total_s": round(render_s + bake_s, 3),
                            "rel_rms_error": round(e, 5), "raw_rms_error": round(raw, 5),
                            "mean_ratio": round(ratio, 5)})
        print(out["rows"][-1], flush=True)

    # the move's camera: an orbit from the 320x180 camera, keyed per frame
    move_cam = bpy.data.objects.new("Move", cam.data.copy())
    scene.collection.objects.link(move_cam)
    for f in range(1, MOVE["frames"] + 1):
        turn = math.radians(MOVE["turn_deg"]) * (f - 1) / (MOVE["frames"] - 1)
        place_camera(MOVE["frame"], turn)
        move_cam.location, move_cam.rotation_euler = cam.location.copy(), cam.rotation_euler.copy()
        move_cam.data.lens = cam.data.lens
        move_cam.keyframe_insert("location", frame=f)
        move_cam.keyframe_insert("rotation_euler", frame=f)
    scene.frame_set(1)

    # native first: the bake mutes the splats for our renders
    refs, frames = {}, [f for f in args["frames"] if f in FRAMES]
    for frame in frames:
        place_camera(frame)
        refs[frame] = ref = Reference(frame, args["reference"][frame])
        for denoise in (False, True):
            for n in args["samples"][frame]:
                px, s = render("CYCLES", n, denoise)
                row(frame, ref, "native Cycles" + (" + denoiser" if denoise else ""), n, s, px)
    move_refs = None
    if args["move"]:
        place_camera(MOVE["frame"])
        first = refs.get(MOVE["frame"]) or Reference(MOVE["frame"], args["reference"][MOVE["frame"]])
        scene.camera = move_cam
        scene.frame_set(MOVE["frames"])
        last = Reference("move last", args["reference"][MOVE["frame"]])
        scene.camera = cam
        scene.frame_set(1)
        move_refs = (first, last)
        for denoise in (False, True):
            for n in args["move_samples"]:
                px, s = render_move("CYCLES", n, denoise)
                row("move", first, "native Cycles" + (" + denoiser" if denoise else ""), n, s, px, refs=move_refs)
    # ours: a probe at the sphere, default settings (Lighting Auto), baked from the same room
    probe = bs.add_probe(at, room)
    assert probe.gs_ibl_probe.lighting == "AUTO"
    t0 = time.perf_counter()
    gb.bake_into_world(scene, probe)
    out["bake_first_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, report, _ = gb.bake_into_world(scene, probe)
    bake_s = out["bake_s"] = time.perf_counter() - t0
    out["bake_report"] = report
    out["auto_choice"] = sphere.get("gs_ibl_grid_key")
    out["probe"] = list(at)
    out["sphere_box"] = [list(at - Vector((radius,) * 3)), list(at + Vector((radius,) * 3))]
    place_camera(frames[0] if frames else MOVE["frame"])
    _, out["eevee_first_frame_s"] = render(eevee, 1)  # shader compilation: once per session, not per frame

    def ours(label: str, bake_s: float) -> None:
        """Our renders of every frame and the move with the bake in place, as ``label`` + engine."""
        for frame in frames:
            place_camera(frame)
            for n in args["our_cycles_samples"][frame]:
                px, s = render("CYCLES", n)
                row(frame, refs[frame], f"{label} + Cycles", n, s, px, bake_s)
            for n in args["eevee_samples"][frame]:
                px, s = render(eevee, n)
                row(frame, refs[frame], f"{label} + EEVEE", n, s, px, bake_s)
        if move_refs:
            for n in args["move_our_cycles_samples"]:
                px, s = render_move("CYCLES", n)
                row("move", move_refs[0], f"{label} + Cycles", n, s, px, bake_s, refs=move_refs)
            for n in args["move_eevee_samples"]:
                px, s = render_move(eevee, n)
                row("move", move_refs[0], f"{label} + EEVEE", n, s, px, bake_s, refs=move_refs)

    ours("our bake", bake_s)
    if "volume" in args.get("lighting", ()):
        # Lighting Volume on the same probe (issue 37): its first bake compiles what Auto's did not, the second is
        # the warm re-bake timed, as Auto's is
        probe.gs_ibl_probe.lighting = "VOLUME"
        gb.bake_into_world(scene, probe)
        t0 = time.perf_counter()
        _, report, _ = gb.bake_into_world(scene, probe)
        volume_s = out["volume_bake_s"] = time.perf_counter() - t0
        out["volume_bake_report"] = report
        ours(VOLUME_LABEL, volume_s)
    return out


# ---------------------------------------------------------------------------------------------------- the host

def _device() -> str:
    sys.path.insert(0, REPO)
    from gs_ibl_addon.core.vk import get_context
    name = get_context().device_name.lower()
    return "lavapipe" if "llvmpipe" in name else name.replace(" ", "-")


GPU_SUFFIX = " on the GPU machine (core, clock held) + EEVEE here"  # a GPU series: "<our label><GPU_SUFFIX>"
STYLES = {"native Cycles": ("tab:red", "o-"), "native Cycles + denoiser": ("tab:orange", "s--"),
          "our bake + Cycles": ("tab:blue", "o-"), "our bake + EEVEE": ("tab:green", "^-"),
          f"our bake{GPU_SUFFIX}": ("tab:purple", "v:"),
          f"{VOLUME_LABEL} + Cycles": ("tab:cyan", "D-"), f"{VOLUME_LABEL} + EEVEE": ("tab:olive", "P-"),
          f"{VOLUME_LABEL}{GPU_SUFFIX}": ("tab:brown", "X:")}
GPU_BAKES = {"our bake": "auto_bake_core_nvidia-*.csv", VOLUME_LABEL: "volume_bake_core_nvidia-*.csv"}
PANELS = ("48x48", "320x180", "960x540", "move")


def gpu_series(rows: list[dict], gpu_bakes: dict[str, float]) -> list[dict]:
    """Our EEVEE rows again, each of Auto and Volume with its bake's time taken from the GPU machine (core, same
    settings; ``gpu_bakes``: {our label: seconds})."""
    return [{**r, "method": f"{label}{GPU_SUFFIX}", "bake_s": s, "total_s": float(r["render_s"]) + s}
            for label, s in gpu_bakes.items() for r in rows if r["method"] == f"{label} + EEVEE"]


def native_time_at(rows: list[dict], frame: str, error: float, method: str) -> tuple[float, str] | None:
    """The time native ``method`` (with or without the denoiser) takes to reach ``error`` in ``frame``: log-log
    interpolation between measured samples; past the last one without the denoiser, Monte Carlo's error ~
    1/sqrt(time) ("extrapolated"); None when it does not reach it (or ``error`` is 0: below the references' noise)."""
    if error <= 0:
        return None
    pts = sorted((float(r["total_s"]), float(r["rel_rms_error"])) for r in rows
                 if r["frame"] == frame and r["method"] == method)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 >= error >= e1 and e0 > e1:
            f = np.log(e0 / error) / np.log(e0 / e1)
            return t0 * (t1 / t0) ** f, "measured"
    if pts and pts[0][1] <= error:
        return pts[0][0], "fewest samples already below"
    if pts and method == "native Cycles":
        return pts[-1][0] * (pts[-1][1] / error) ** 2, "extrapolated"
    return None


def speedups(rows: list[dict]) -> list[dict]:
    """Per panel and our method: our fastest point (least time x error^2), and each native series' time to the
    same error."""
    out = []
    for frame in PANELS:
        for method in (m for m in STYLES if not m.startswith("native")):
            ours = [r for r in rows if r["frame"] == frame and r["method"] == method]
            if not ours:
                continue
            best = min(ours, key=lambda r: float(r["total_s"]) * float(r["rel_rms_error"]) ** 2)
            entry = {"frame": frame, "method": method, "samples": best["samples"],
                     "error": float(best["rel_rms_error"]), "ours_s": float(best["total_s"])}
            for key, native in (("plain", "native Cycles"), ("denoised", "native Cycles + denoiser")):
                t = native_time_at(rows, frame, entry["error"], native)
                entry[key] = (t[0], t[1], t[0] / entry["ours_s"]) if t else None
            out.append(entry)
    return out


def _plot(rows: list[dict], out_png: str, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    panels = [p for p in PANELS if any(r["frame"] == p for r in rows)]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.4 * len(panels), 4.6), squeeze=False)
    for ax, frame in zip(axes[0], panels):
        for method, (colour, style) in STYLES.items():
            pts = sorted((float(r["total_s"]), float(r["rel_rms_error"]), r["samples"]) for r in rows
                         if r["method"] == method and r["frame"] == frame)
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [100 * max(p[1], 1e-4) for p in pts], style, color=colour, label=method)
            for i, (t, e, n) in enumerate(pts):  # labels alternate above and below: near points stay readable
                ax.annotate(str(n), (t, 100 * max(e, 1e-4)), textcoords="offset points",
                            xytext=(4, 4 if i % 2 else -10), fontsize=6, color=colour)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time, s (ours: bake + render)")
        ax.set_title(f"24-frame move at {MOVE['frame']}, bake once" if frame == "move" else f"{frame} frame",
                     fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("per-pixel error vs native Cycles, % (rel. RMS)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    for ax in axes[0][1:]:  # every method once, below the panels
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    rows_of_legend = -(-len(labels) // 5)  # five a row: nine series did not fit one row of the figure's width
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 5), fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=8)
    fig.tight_layout(rect=(0, 0.05 + 0.04 * rows_of_legend, 1, 1))
    fig.savefig(out_png, dpi=120)


def _title(blender, device, threads, date, gpu_note) -> str:
    return (f"White sphere (albedo 0.8, 33/70/210 px wide) in the sample room, Blender {blender}, {device} "
            f"({threads} threads), {date}; ours: Lighting Auto and Volume, panel defaults; error against two "
            f"independent native Cycles renders (denoiser off), their own noise removed; labels: samples{gpu_note}")


def _read_gpu_bakes(folder: str) -> tuple[dict[str, float], str]:
    """({our label: the GPU machine's bake, seconds}, the title's note): per bake the newest row of its CSVs in
    ``folder`` (auto_bake_core.py writes them, one per device)."""
    import csv
    import glob
    out, notes = {}, []
    for label, pattern in GPU_BAKES.items():
        rows = [r for path in glob.glob(os.path.join(folder, pattern)) for r in csv.DictReader(open(path))]
        if not rows:
            continue
        row = rows[max(range(len(rows)), key=lambda i: (rows[i]["date"], i))]  # a day's last row is its newest
        out[label] = float(row["wall_s"])
        notes.append(f"{label}: {row['device']}, driver {row['driver']}, SM {row['sm_mhz']} MHz, {row['date']}, "
                     f"{float(row['wall_s']):.3f} s wall")
    return out, ("\nGPU bakes (core): " + "; ".join(notes)) if notes else ""


def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x]


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--in-blender":
        print(RESULT_TAG + json.dumps(_in_blender(json.load(open(sys.argv[2])))), flush=True)
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", default="48x48,320x180,960x540", help="which of " + ", ".join(FRAMES))
    ap.add_argument("--no-move", action="store_true", help="leave the 24-frame move out")
    ap.add_argument("--lighting", default="auto,volume", help="our series: auto (always), volume (Lighting Volume "
                    "on the same probe, baked after Auto's renders)")
    ap.add_argument("--quick", action="store_true", help="a smoke run: few samples everywhere (a chart of noise)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--csv", default=None)
    ap.add_argument("--png", default=os.path.join(REPO, "docs", "native-vs-ours.png"))
    ap.add_argument("--gpu-bakes", default=os.path.join(REPO, "docs", "bench"),
                    help="the folder of the GPU machine's bake times (benchmarks/auto_bake_core.py's CSVs)")
    ap.add_argument("--plot-only", metavar="CSV", help="redraw the chart of an earlier run's CSV and stop")
    a = ap.parse_args()
    gpu_bakes, gpu_note = _read_gpu_bakes(a.gpu_bakes)
    if a.plot_only:
        import csv
        rows = [r for r in csv.DictReader(open(a.plot_only)) if "(core, clock held)" not in r["method"]]
        rows += gpu_series(rows, gpu_bakes)
        r0 = rows[0]
        _plot(rows, a.png, _title(r0["blender"], r0["device"], a.threads, r0["date"], gpu_note))
        _print_speedups(rows)
        return
    sys.path.insert(0, os.path.join(REPO, "tests", "real_blender"))
    import test_matrix as matrix
    matrix.TIMEOUT_S = 3 * 3600  # the matrix's per-command limit is for tests; a full run here takes ~35 min
    entry = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
    if not matrix._ready(entry.root):
        sys.exit(f"the bpy 5.3 root is not made: scripts/blender_roots.sh ensure {entry.root}")
    device = _device()
    csv_path = a.csv or os.path.join(REPO, "docs", "bench", f"native_{device}.csv")
    work = os.path.join(REPO, "out", "bench", "native")
    os.makedirs(work, exist_ok=True)
    zip_path = os.path.join(work, "gs_ibl.zip")
    subprocess.run([sys.executable, "scripts/build_extension.py", "--output", zip_path], cwd=REPO, check=True,
                   capture_output=True, text=True)
    runner = matrix.Runner(entry, None)
    frames = [f for f in a.frames.split(",") if f]
    try:
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        shutil.copy(os.path.join(REPO, "samples", "room.ply"), runner.host / "room.ply")
        shutil.copy(os.path.abspath(__file__), runner.host / "native_bench.py")
        shutil.copy(bs.__file__, runner.host / "blender_scene.py")
        # samples per frame: the larger frames stop where native's time runs to minutes on this CPU
        args = {"work": str(runner.inner), "room": str(runner.inner / "room.ply"), "threads": a.threads,
                "frames": frames, "move": not a.no_move, "lighting": a.lighting.split(","),
                "reference": {"48x48": 4096, "320x180": 1024, "960x540": 512},
                "samples": {"48x48": [16, 64, 256, 1024], "320x180": [16, 64, 256], "960x540": [16, 64, 256]},
                "our_cycles_samples": {"48x48": [16, 64, 256], "320x180": [16, 64, 256], "960x540": [16, 64]},
                "eevee_samples": {"48x48": [1, 4, 16], "320x180": [1, 4], "960x540": [1, 4]},
                "move_samples": [16, 64], "move_our_cycles_samples": [16], "move_eevee_samples": [1, 4],
                "probe_in_room": list(bs.ROOM_SPHERE["centre"])}
        if a.quick:
            for key in ("reference", "samples", "our_cycles_samples", "eevee_samples"):
                args[key] = {f: (64 if key == "reference" else [4]) for f in FRAMES}
            args.update(move_samples=[4], move_our_cycles_samples=[4], move_eevee_samples=[1])
            csv_path, a.png = os.path.join(work, "quick.csv"), os.path.join(work, "quick.png")
        (runner.host / "args.json").write_text(json.dumps(args))
        assert matrix._install(runner, str(runner.inner / "gs_ibl.zip")).returncode == 0, "install failed"
        r = runner.run([runner.python(), str(runner.inner / "native_bench.py"), "--in-blender",
                        str(runner.inner / "args.json")], "bench")
        line = next((x for x in r.stdout.splitlines() if x.startswith(RESULT_TAG)), None)
        if line is None:
            sys.exit(f"no result (rc {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
        result = json.loads(line[len(RESULT_TAG):])
    finally:
        runner.close()
    stamp = time.strftime("%Y-%m-%d", time.gmtime())
    ref_of = {f: v["reference_samples"] for f, v in result["frames"].items()}
    rows = [{"date": stamp, "device": device, "blender": result["blender"],
             "reference": ref_of.get(row["frame"] if row["frame"] != "move" else MOVE["frame"], ""), **row}
            for row in result["rows"]]
    from bench_common import append_csv
    if os.path.exists(csv_path):
        os.remove(csv_path)  # one run per file: the chart is of one run
    append_csv(csv_path, rows)
    json_path = os.path.splitext(csv_path)[0] + ".json"
    with open(json_path, "w") as f:
        json.dump({k: v for k, v in result.items() if k != "rows"}, f, indent=1)
    rows += gpu_series(rows, gpu_bakes)
    _plot(rows, a.png, _title(result["blender"], device, a.threads, stamp, gpu_note))
    print(f"references: {json.dumps(result['frames'])}\nour bake {result['bake_s']:.2f} s (first of the session "
          f"{result['bake_first_s']:.2f} s, Auto chose {result['auto_choice']}): {result['bake_report']}; "
          f"EEVEE's first frame (shaders) {result['eevee_first_frame_s']:.1f} s")
    if "volume_bake_s" in result:
        print(f"Lighting Volume's bake {result['volume_bake_s']:.2f} s: {result['volume_bake_report']}")
    print("| frame | method | samples | render s | bake s | total s | rel. RMS error | raw | mean / reference |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for row in result["rows"]:
        print(f"| {row['frame']} | {row['method']} | {row['samples']} | {row['render_s']:.2f} | "
              f"{row['bake_s']:.2f} | {row['total_s']:.2f} | {100 * row['rel_rms_error']:.2f}% | "
              f"{100 * row['raw_rms_error']:.2f}% | {row['mean_ratio']:.3f} |")
    _print_speedups(rows)
    print(f"\n{csv_path}\n{json_path}\n{a.png}")


def _print_speedups(rows: list[dict]) -> None:
    print("\n| frame | ours | samples | error | ours s | native, no denoiser: s (how), ours faster | "
          "native + denoiser: s (how), ours faster |")
    print("|---|---|---:|---:|---:|---|---|")

    def cell(v):
        return "not reached" if v is None else f"{v[0]:.1f} ({v[1]}), **{v[2]:.1f}x**"
    for s in speedups(rows):
        print(f"| {s['frame']} | {s['method']} | {s['samples']} | {100 * s['error']:.2f}% | {s['ours_s']:.1f} | "
              f"{cell(s['plain'])} | {cell(s['denoised'])} |")


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    main()
