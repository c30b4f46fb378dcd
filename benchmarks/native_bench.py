"""Speed against Blender's native splats (issue 16, part 5): time against per-pixel error for a lit mesh in the sample
room, Blender 5.3's Cycles path-tracing the native splats (16-4096 samples, denoiser off and on) against our bake + a
Cycles render and our bake + EEVEE. Same machine, same run, one Blender (bpy 5.3 in the trixie root, with the built
zip installed by Blender's own installer, as tests/real_blender/ does).

Run:  python benchmarks/native_bench.py [--size 48] [--reference 8192] [--samples 16,64,256,1024,4096]
Needs the trixie root (scripts/blender_roots.sh ensure trixie). Writes docs/bench/native_<device>.csv and
docs/native-vs-ours.png, and prints a markdown table.

The scene: samples/room.ply imported by our importer (on 5.3 a native Gaussian-splat Point Cloud), a white diffuse
sphere (albedo 0.8, radius 0.3 m) where the matrix puts it, the matrix's camera. The splats are hidden from the camera
(film transparent) so every error is the sphere's light. Reference: native Cycles at --reference samples, denoiser
off, another seed. Error: RMS over the sphere's pixels of (render - reference), over the reference's RMS, RGB pooled;
it holds the reference's own noise (about 1/sqrt(reference / samples) of a run's) and, for ours, the bias of one probe
for a whole sphere. Time: wall seconds of the render call; ours adds the bake (the first bake of the session, Vulkan
start included, and a warm re-bake, both recorded).

Inside Blender this same file runs with --in-blender ARGS.json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, ".."))
RESULT_TAG = "GSIBL-NATIVE-BENCH "
MODULE = "bl_ext.user_default.gs_ibl"


# ---------------------------------------------------------------------------------------------------- in Blender

def _in_blender(args: dict) -> dict:
    import importlib

    import bpy
    import addon_utils  # noqa: I001 (importable once bpy is)
    import numpy as np
    from mathutils import Vector

    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)
    gb = importlib.import_module(f"{MODULE}.blender.bake")
    so = importlib.import_module(f"{MODULE}.blender.splat_object")
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("Black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    assert bpy.ops.gs_ibl.import_splats(filepath=args["room"]) == {"FINISHED"}
    room = bpy.context.active_object
    out = {"blender": bpy.app.version_string, "native": so.is_native_splats(room), "rows": []}
    at = room.matrix_world @ Vector(args["probe_in_room"])
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=at, segments=64, ring_count=32)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("White")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    nt.links.new(diffuse.outputs["BSDF"], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    sphere.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = at + Vector((0.0, -1.2, 0.25))
    cam.rotation_euler = (at - cam.location).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 50.0
    scene.camera = cam
    r = scene.render
    r.resolution_x = r.resolution_y = args["size"]
    r.resolution_percentage = 100
    r.film_transparent = True
    r.image_settings.file_format = "OPEN_EXR"
    r.threads_mode = "FIXED"
    r.threads = args["threads"]
    room.visible_camera = False  # the sphere alone in the picture: every error is its light
    scene.view_settings.view_transform = "Standard"
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.transparent_max_bounces = 64

    def render(engine: str, samples: int, denoise: bool = False, seed: int = 0):
        r.engine = engine
        if engine == "CYCLES":
            c.samples, c.use_denoising, c.seed = samples, denoise, seed
            if denoise:
                c.denoiser = "OPENIMAGEDENOISE"
        else:
            scene.eevee.taa_render_samples = samples
        path = os.path.join(args["work"], "frame.exr")
        r.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - t0
        img = bpy.data.images.load(path)
        px = np.empty(len(img.pixels), np.float32)
        img.pixels.foreach_get(px)
        bpy.data.images.remove(img)
        return px.reshape(args["size"], args["size"], 4), seconds

    ref, ref_s = render("CYCLES", args["reference"], seed=1)
    mask = ref[..., 3] > 0.99
    out.update(reference_samples=args["reference"], reference_s=ref_s, sphere_pixels=int(mask.sum()))
    ref_rgb = ref[mask][:, :3].astype(np.float64)

    def error(px) -> float:
        d = px[mask][:, :3].astype(np.float64) - ref_rgb
        return float(np.sqrt(np.mean(d ** 2)) / np.sqrt(np.mean(ref_rgb ** 2)))

    def row(method: str, samples: int, render_s: float, px, bake_s: float = 0.0) -> None:
        out["rows"].append({"method": method, "samples": samples, "render_s": round(render_s, 3),
                            "bake_s": round(bake_s, 3), "total_s": round(render_s + bake_s, 3),
                            "rel_rms_error": round(error(px), 5),
                            "mean_ratio": round(float(px[mask][:, :3].mean() / ref_rgb.mean()), 5)})
        print(out["rows"][-1], flush=True)

    for denoise in (False, True):
        for n in args["samples"]:
            px, s = render("CYCLES", n, denoise)
            row("native Cycles" + (" + denoiser" if denoise else ""), n, s, px)
    # ours: a probe at the sphere, default settings, baked from the same room (the bake mutes the splats' bounces)
    bpy.ops.object.empty_add(location=at)
    probe = bpy.context.active_object
    probe.gs_ibl_probe.is_probe, probe.gs_ibl_probe.splats = True, room
    probe.gs_ibl_probe.lighting = "WORLD"  # this chart is of one probe (Lighting Auto: issue 22's next chart)
    t0 = time.perf_counter()
    gb.bake_into_world(scene, probe)
    out["bake_first_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, report, _ = gb.bake_into_world(scene, probe)
    bake_s = out["bake_s"] = time.perf_counter() - t0
    out["bake_report"] = report
    for n in args["samples"]:
        if n <= 1024:
            px, s = render("CYCLES", n)
            row("our bake + Cycles", n, s, px, bake_s)
    eevee = next(e for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE")
                 if e in {i.identifier for i in r.bl_rna.properties["engine"].enum_items})
    _, out["eevee_first_frame_s"] = render(eevee, 1)  # shader compilation: once per session, not per frame
    for n in args["eevee_samples"]:
        px, s = render(eevee, n)
        row("our bake + EEVEE", n, s, px, bake_s)
    return out


# ---------------------------------------------------------------------------------------------------- the host

def _device() -> str:
    sys.path.insert(0, REPO)
    from gs_ibl_addon.core.vk import get_context
    name = get_context().device_name.lower()
    return "lavapipe" if "llvmpipe" in name else name.replace(" ", "-")


def _plot(rows: list[dict], out_png: str, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    styles = {"native Cycles": ("tab:red", "o-"), "native Cycles + denoiser": ("tab:orange", "s--"),
              "our bake + Cycles": ("tab:blue", "o-"), "our bake + EEVEE": ("tab:green", "^-")}
    for method, (colour, style) in styles.items():
        pts = sorted((r["total_s"], r["rel_rms_error"], r["samples"]) for r in rows if r["method"] == method)
        if not pts:
            continue
        ax.plot([p[0] for p in pts], [100 * p[1] for p in pts], style, color=colour, label=method)
        for i, (t, e, n) in enumerate(pts):  # labels alternate above and below: near points stay readable
            ax.annotate(str(n), (t, 100 * e), textcoords="offset points", xytext=(4, 4 if i % 2 else -10),
                        fontsize=7, color=colour)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time, s (ours: bake + render)")
    ax.set_ylabel("per-pixel error vs native reference, % (rel. RMS)")
    ax.set_title(title, fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)


def _title(size, blender, device, threads, date, reference) -> str:
    return (f"White sphere (albedo 0.8) in the sample room, {size}x{size} px, Blender {blender}, {device}, "
            f"{threads} threads, {date}\nerror against native Cycles at {reference} spp (denoiser off); "
            "labels: samples")


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--in-blender":
        print(RESULT_TAG + json.dumps(_in_blender(json.load(open(sys.argv[2])))), flush=True)
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=48)
    ap.add_argument("--reference", type=int, default=8192)
    ap.add_argument("--samples", default="16,64,256,1024,4096")
    ap.add_argument("--eevee-samples", default="1,4,16")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--csv", default=None)
    ap.add_argument("--png", default=os.path.join(REPO, "docs", "native-vs-ours.png"))
    ap.add_argument("--plot-only", metavar="CSV", help="redraw the chart of an earlier run's CSV and stop")
    a = ap.parse_args()
    if a.plot_only:
        import csv
        rows = list(csv.DictReader(open(a.plot_only)))
        for row in rows:
            row.update(total_s=float(row["total_s"]), rel_rms_error=float(row["rel_rms_error"]))
        r0 = rows[0]
        _plot(rows, a.png, _title(r0["size"], r0["blender"], r0["device"], a.threads, r0["date"], r0["reference"]))
        return
    sys.path.insert(0, os.path.join(REPO, "tests", "real_blender"))
    import test_matrix as matrix
    matrix.TIMEOUT_S = 3 * 3600  # the matrix's per-command limit is for tests; a full run here takes ~20 min
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
    try:
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        shutil.copy(os.path.join(REPO, "samples", "room.ply"), runner.host / "room.ply")
        shutil.copy(os.path.abspath(__file__), runner.host / "native_bench.py")
        args = {"work": str(runner.inner), "room": str(runner.inner / "room.ply"), "size": a.size,
                "reference": a.reference, "samples": [int(x) for x in a.samples.split(",")],
                "eevee_samples": [int(x) for x in a.eevee_samples.split(",")], "threads": a.threads,
                "probe_in_room": [0.0, 0.45, 1.0]}
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
    rows = [{"date": stamp, "device": device, "blender": result["blender"], "size": a.size,
             "reference": result["reference_samples"], **row}
            for row in result["rows"]]
    from bench_common import append_csv
    if os.path.exists(csv_path):
        os.remove(csv_path)  # one run per file: the chart is of one run
    append_csv(csv_path, rows)
    _plot(result["rows"], a.png, _title(a.size, result["blender"], device, a.threads, stamp,
                                        result["reference_samples"]))
    print(f"reference: native Cycles {result['reference_samples']} spp, {result['reference_s']:.1f} s, "
          f"{result['sphere_pixels']} sphere pixels; our bake {result['bake_s']:.2f} s (first of the session "
          f"{result['bake_first_s']:.2f} s): {result['bake_report']}; EEVEE's first frame (shaders) "
          f"{result['eevee_first_frame_s']:.1f} s")
    native = {r["samples"]: r["rel_rms_error"] for r in result["rows"] if r["method"] == "native Cycles"}
    if native:  # error^2 = k (1/n + 1/reference): the reference's own share at the largest n
        n, ref = max(native), result["reference_samples"]
        print(f"the reference's own per-pixel noise: about {native[n] * (1 / ref / (1 / n + 1 / ref)) ** 0.5:.2%}\n")
    print("| method | samples | render s | bake s | total s | rel. RMS error | mean / reference |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for row in result["rows"]:
        print(f"| {row['method']} | {row['samples']} | {row['render_s']:.2f} | {row['bake_s']:.2f} | "
              f"{row['total_s']:.2f} | {100 * row['rel_rms_error']:.2f}% | {row['mean_ratio']:.3f} |")
    print(f"\n{csv_path}\n{a.png}")


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    main()
