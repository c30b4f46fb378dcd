"""A capture in a final render three ways (issue 36, items 1 and 5): Blender 5.3's native Gaussian-splat objects in
Cycles and in EEVEE, and our F12 path drawing the same capture, each timed per frame and compared with gsplat 1.5.3's
classic image of the same camera (3DGS's look).

Two halves:

``refs`` (the GPU machine: benchmarks/gpu_run.sh refs): per capture (the guitar, the sample room) and view
(fidelity_bench.camera_views: its eight views, its camera conventions), gsplat's classic image at the comparison
size (--size, default 480x270: what native Cycles affords on this machine's CPU) and ours (core render_camera,
fidelity_bench.Ours) beside it; at 1920x1080 our time per frame (GPU by timestamps, wall with the image read back)
and gsplat's (wall, synchronised, read back), and our PSNR against gsplat there. Into --out: refs_<capture>.npz
(float16 premultiplied RGBA, top row first: gsplat_<view>, ours_<view>, and the camera of each view), refs.csv,
refs_<capture>.png (the views, gsplat above ours, 8-bit). Where CUDA is missing the peer is the numpy port of gsplat
classic (fidelity_bench.ClassicNumpy, --peer numpy) or our own image (--peer ours): the rows say which.

``bench`` (here: the trixie root's bpy 5.3 with the built zip installed by Blender's installer, as
tests/real_blender/ runs it): the capture imported by our importer (a native Gaussian-splat Point Cloud on 5.3),
per view a camera as fidelity_bench places it (through the object's matrix), and
- native Cycles (CPU, --cycles-samples, denoiser off: its noise counts against it) and native EEVEE
  (--eevee-samples) at the comparison size,
- ours: the same Blender's F12 with Native Splats set to GS-IBL (the extension draws the point cloud), at the
  comparison size and at 1920x1080,
each frame's wall time (bpy.ops.render.render, the EXR written) and PSNR against the reference image of the same
view (docs/bench/native_frame_refs/refs_<capture>.npz from the GPU machine; a missing one is made here with
--stand-in: the numpy port, or ours). Blender's linear result is compared as its Standard view shows it (sRGB
encoded), with gsplat's raw values as 3DGS's viewers show them.

  python benchmarks/native_frame_bench.py refs [--captures guitar,room] [--size 480x270] [--out DIR] [--peer auto]
  python benchmarks/native_frame_bench.py bench [--captures guitar,room] [--views v0,v4] [--refs DIR]
  python benchmarks/native_frame_bench.py plot --csv docs/bench/native_frame_lavapipe.csv --png docs/img/...
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

# tests/real_blender/blender_scene.py: here from the repository, in Blender copied beside this file
sys.path.insert(0, os.path.join(ROOT, "tests", "real_blender"))
import blender_scene as bs  # noqa: E402
from blender_scene import MODULE  # noqa: E402

REFS_DIR = os.path.join(ROOT, "docs", "bench", "native_frame_refs")
FULL = (1920, 1080)
T0 = time.perf_counter()


def log(*a) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s]", *a, flush=True)


def to_8bit(img: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 of a premultiplied float image over black (gsplat's raw values as a 3DGS viewer shows them)."""
    return (np.clip(img[..., :3], 0, 1) * 255 + 0.5).astype(np.uint8)


class StandIn:
    """Our own image as the reference (no CUDA, no time for the numpy port): agreement with it is 'as ours'."""
    name = "gs-ibl (stand-in)"

    def __init__(self, ours, scene, near: float, far: float) -> None:
        import fidelity_bench as fb
        from dataclasses import replace
        self.ours = ours
        self.srgb = fb.Ours(replace(scene, colour_space="srgb"), near, far, ours.r.ctx)

    def render(self, cv) -> np.ndarray:
        return self.ours.render(cv)


def make_reference(kind: str, scene, near: float, far: float, ours):
    """gsplat on CUDA (auto, gsplat), else the numpy port (numpy) or our own image (ours)."""
    import fidelity_bench as fb
    if kind == "ours":
        return StandIn(ours, scene, near, far)
    if kind == "numpy":
        return fb.ClassicNumpy(scene, near, far)
    return fb.make_peer(kind, scene, near, far)


def linear_rule(ref, scene, cv, space: str) -> np.ndarray | None:
    """For a capture in sRGB: the reference's splats blended by Blender's rule (each splat's colour decoded to
    linear light, blended, the result encoded again: what any Blender render of them shows in its Standard view),
    where gsplat blends the sRGB values themselves. None for a linear capture (the rules agree)."""
    import fidelity_bench as fb
    from gs_ibl_addon.core.colour import linear_to_srgb, srgb_to_linear
    from gs_ibl_addon.core.sh import eval_sh_color
    if space != "srgb":
        return None
    if isinstance(ref, StandIn):
        img = ref.srgb.render(cv)
    elif isinstance(ref, fb.GsplatCuda):
        torch = ref.torch
        d = scene.positions.astype(np.float64) - cv.matrix[:3, 3]
        rgb = srgb_to_linear(eval_sh_color(scene.sh, d / np.linalg.norm(d, axis=1, keepdims=True)))
        colours = torch.from_numpy(np.ascontiguousarray(rgb, np.float32)).cuda()
        vm, k = fb.opencv_camera(cv)
        tt = lambda a: torch.tensor(np.array(a)[None], dtype=torch.float32, device="cuda")  # noqa: E731
        c, a, _ = ref.raster(*ref.t[:4], colours, tt(vm), tt(k), cv.width, cv.height, sh_degree=None,
                             near_plane=ref.near, far_plane=ref.far, rasterize_mode="classic", packed=True)
        img = np.concatenate([c[0].float().cpu().numpy(), a[0].float().cpu().numpy()], -1)
    elif isinstance(ref, fb.ClassicNumpy):
        class Decoded(fb.ClassicNumpy):
            def project(self, cv):
                p = super().project(cv)
                p["color"] = srgb_to_linear(p["color"])
                return p
        img = Decoded(scene, ref.near, ref.far).render(cv)
    else:
        return None
    img = img.astype(np.float32)
    img[..., :3] = linear_to_srgb(np.clip(img[..., :3], 0, None))
    return img


def time_frames(step, rounds: int = 5) -> list[float]:
    """Wall ms of ``rounds`` calls of ``step`` after one warm-up call (pipelines, buffers sized by the first)."""
    step()
    out = []
    for _ in range(rounds):
        t = time.perf_counter()
        step()
        out.append((time.perf_counter() - t) * 1e3)
    return out


def run_refs(args) -> None:
    import fidelity_bench as fb
    from bench_common import append_csv, gpu_clock, hold_gpu_clock
    from gs_ibl_addon.core.formats import read_scene
    from gs_ibl_addon.core.vk import get_context
    hold = hold_gpu_clock()  # noqa: F841 - the CUDA context holds the SM clock (shared/NOTES-vulkan-and-gpu.md)
    ctx = get_context()
    w, h = fb.parse_size(args.size)
    date = datetime.date.today().isoformat()
    os.makedirs(args.out, exist_ok=True)
    csv_path = os.path.join(args.out, "refs.csv")
    if os.path.exists(csv_path):
        os.remove(csv_path)
    for spec in [s for s in args.captures.split(",") if s]:
        name, path, up = fb.parse_capture(spec)
        scene = fb.load_capture(path)
        space = read_scene(path).colour_space  # the file's own (load_capture reads its SH as linear values)
        ours = fb.Ours(scene, args.near, args.far, ctx)
        ref = make_reference(args.peer, scene, args.near, args.far, ours)
        log(f"{name}: {scene.count:,} splats, reference: {ref.name}, {ctx.device_name}")
        small = fb.camera_views(scene, up, w, h, args.fov)
        full = fb.camera_views(scene, up, *FULL, args.fov)
        arrays, rows = {}, []
        for cv, cf in zip(small, full):
            if args.views and cv.name not in args.views.split(","):
                continue
            a, b = ours.render(cv), ref.render(cv)
            arrays[f"ours_{cv.name}"], arrays[f"gsplat_{cv.name}"] = a.astype(np.float16), b.astype(np.float16)
            arrays[f"camera_{cv.name}"] = np.array([*cv.matrix.ravel(), cv.tan_x, cv.tan_y, *cv.shift])
            lin = linear_rule(ref, scene, cv, space)
            if lin is not None:
                arrays[f"gsplat_lin_{cv.name}"] = lin.astype(np.float16)
            row = {"device": ctx.device_name, "reference": ref.name, "date": date, "capture": name,
                   "splats": scene.count, "view": cv.name, "core_radii": cv.factor, "width": w, "height": h,
                   "psnr_small": fb.compare(a, b)["psnr"]}
            if not args.no_full:
                fa = ours.render(cf)
                gpu = []

                def ours_step(cf=cf, ours=ours, gpu=gpu) -> None:
                    f = ours.r.render_camera(fb.our_batch(cf), cut=np.full((cf.height, cf.width), args.far,
                                                                            np.float32), depth=False, timestamps=True)
                    gpu.append(f.timings["total"])
                wall = time_frames(ours_step, args.rounds)
                row.update({"ours_full_gpu_ms": round(statistics.median(gpu[1:]), 3),
                            "ours_full_wall_ms": round(statistics.median(wall), 2)})
                if isinstance(ref, fb.GsplatCuda):
                    fb_img = ref.render(cf)
                    row["ref_full_wall_ms"] = round(statistics.median(time_frames(lambda cf=cf, ref=ref: ref.render(cf),
                                                                                  args.rounds)), 2)
                    row["psnr_full"] = fb.compare(fa, fb_img)["psnr"]
                else:
                    row["ref_full_wall_ms"], row["psnr_full"] = "", ""
                row["sm_mhz"] = gpu_clock()
            rows.append(row)
            log(f"  {name} {cv.name}: ours vs {ref.name} {row['psnr_small']:.2f} dB at {w}x{h}"
                + ("" if args.no_full else f"; 1920x1080 ours GPU {row['ours_full_gpu_ms']} ms, wall "
                   f"{row['ours_full_wall_ms']} ms, reference wall {row['ref_full_wall_ms']} ms, PSNR "
                   f"{row['psnr_full']}"))
        np.savez_compressed(os.path.join(args.out, f"refs_{name}.npz"), reference=np.array(ref.name),
                            size=np.array([w, h]), up=np.array(up), fov=np.array(args.fov), **arrays)
        append_csv(csv_path, rows)
        save_sheet(os.path.join(args.out, f"refs_{name}.png"), f"{name}: {ref.name} (top)\nand gs-ibl (bottom), "
                   f"{w}x{h}", arrays)
        ours.close()
        if isinstance(ref, StandIn):
            ref.srgb.close()
        del ref
    log(f"wrote {args.out}")


def save_sheet(path: str, title: str, arrays: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    views = sorted(k.split("_", 1)[1] for k in arrays if k.startswith("ours_"))
    fig, axes = plt.subplots(2, len(views), figsize=(2.4 * len(views), 3.0), squeeze=False)
    for j, v in enumerate(views):
        for i, key in enumerate(("gsplat", "ours")):
            axes[i][j].imshow(to_8bit(arrays[f"{key}_{v}"].astype(np.float32)))
            axes[i][j].set_title(f"{v} {key}", fontsize=7)
            axes[i][j].axis("off")
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------- in Blender

RESULT_TAG = "GSIBL-NATIVE-FRAME "


def _in_blender(args: dict) -> dict:
    """Per capture and view: the renders of args["methods"], each EXR saved as float16 .npy beside args.json, and
    a row of its time and checks (stdout's RESULT_TAG line)."""
    import importlib
    import math

    import bpy
    from mathutils import Matrix

    bs.enable_extension()
    frame = importlib.import_module(f"{MODULE}.blender.render.frame")
    compositor = importlib.import_module(f"{MODULE}.blender.render.compositor")
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    scene = bpy.context.scene
    r = scene.render
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.film_transparent = True
    r.threads_mode, r.threads = "FIXED", args["threads"]
    scene.view_settings.view_transform = "Standard"
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False  # a fixed sample count: the samples named are the samples taken
    eevee = bs.eevee_engine()
    work = args["work"]
    out = {"blender": bpy.app.version_string, "rows": [],
           "cycles_defaults": {"transparent_max_bounces": c.transparent_max_bounces,
                               "filter_width": r.filter_size, "denoiser": "OPENIMAGEDENOISE"}}

    def render(method: dict, size: tuple[int, int]) -> tuple[np.ndarray, float]:
        scene.gs_ibl_render.native_splats = method["choice"]
        r.engine = "CYCLES" if method["engine"] == "cycles" else eevee
        if method["engine"] == "cycles":
            c.samples, c.use_denoising = method["samples"], method["denoise"]
            if method["denoise"]:
                c.denoiser = "OPENIMAGEDENOISE"
        else:
            scene.eevee.taa_render_samples = method["samples"]
        r.resolution_x, r.resolution_y = size
        r.filepath = os.path.join(work, "frame.exr")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        return bs.read_image(r.filepath), time.perf_counter() - t0

    for cap in args["captures"]:
        bs.clear("objects", "cameras")
        bs.black_world()
        assert bpy.ops.gs_ibl.import_splats(filepath=cap["path"]) == {"FINISHED"}
        ob = bpy.context.active_object
        assert so.is_native_splats(ob), f"{cap['name']}: not imported as Blender's splats"
        to_world = Matrix(ob.matrix_world)
        cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(cam)
        scene.camera = cam
        warmed = set()
        for view in cap["views"]:
            tan_x, tan_y, sx, sy = view["camera"][16:]
            cam.matrix_world = to_world @ Matrix(np.array(view["camera"][:16]).reshape(4, 4).tolist())
            cam.data.sensor_fit, cam.data.angle = "HORIZONTAL", 2 * math.atan(tan_x)
            cam.data.shift_x, cam.data.shift_y = sx / (2 * tan_x), sy / (2 * tan_x)
            cam.data.clip_start, cam.data.clip_end = args["near"], args["far"]
            for method in args["methods"]:
                for size in method["sizes"]:
                    key = (method["engine"], method["choice"])
                    if key not in warmed:  # kernels, shaders, the splats' first read: once per session
                        r.resolution_percentage = 10
                        _, warm_s = render({**method, "samples": 1}, tuple(size))
                        r.resolution_percentage = 100
                        warmed.add(key)
                        out.setdefault("warm_up_s", {})[f"{cap['name']} {method['name']}"] = round(warm_s, 2)
                    img, seconds = render(method, tuple(size))
                    rec = frame.last_render(scene)["frames"].get(scene.frame_current, {})
                    front = compositor.find_image(scene, scene.view_layers[0].name, compositor.FRONT_ROLE)
                    drew = method["choice"] == "GSIBL" and rec.get("objects") == [ob.name]
                    front_px = None
                    if front is not None and drew and tuple(front.size) == tuple(size):
                        front_px = np.empty(size[0] * size[1] * 4, np.float32)
                        front.pixels.foreach_get(front_px)
                        front_px = front_px.reshape(size[1], size[0], 4)[::-1]
                    row = {"capture": cap["name"], "view": view["name"], "method": method["name"],
                           "engine": method["engine"], "choice": method["choice"], "samples": method["samples"],
                           "denoise": method["denoise"], "width": size[0], "height": size[1],
                           "render_s": round(seconds, 3), "splats_ms": rec.get("ms", "") if drew else "",
                           "ours_drew": bool(drew), "coverage": round(float(img[..., 3].mean()), 4),
                           # the render is our FRONT alone (Blender drew nothing of the splats): want 0
                           "render_minus_front": (round(float(np.abs(img - front_px).max()), 5)
                                                  if front_px is not None else ""),
                           "camera_icon_after": bool(ob.visible_camera), "messages": frame.last_render(scene)
                           ["messages"][:3]}
                    out["rows"].append(row)
                    print(row, flush=True)
                    if tuple(size) == tuple(args["size"]):
                        np.save(os.path.join(work, f"{cap['name']}_{view['name']}_{method['name']}.npy"),
                                img.astype(np.float16))
    return out


# ---------------------------------------------------------------------------------------------------- the host

def methods(args) -> list[dict]:
    """The renders per view: native Cycles (no denoiser, then OIDN), native EEVEE, ours (Native Splats: GS-IBL, in
    Cycles at one sample: the scene holds nothing else) at the comparison size and at 1920x1080."""
    size = list(args.size_wh)
    out = []
    for n in args.cycles_samples:
        out.append({"name": f"native-cycles-{n}", "engine": "cycles", "choice": "BLENDER", "samples": n,
                    "denoise": False, "sizes": [size]})
        if n in args.denoise_samples:
            out.append({"name": f"native-cycles-{n}-oidn", "engine": "cycles", "choice": "BLENDER", "samples": n,
                        "denoise": True, "sizes": [size]})
    for n in args.eevee_samples:
        out.append({"name": f"native-eevee-{n}", "engine": "eevee", "choice": "BLENDER", "samples": n,
                    "denoise": False, "sizes": [size]})
    out.append({"name": "gs-ibl", "engine": "cycles", "choice": "GSIBL", "samples": 1, "denoise": False,
                "sizes": [size] + ([list(FULL)] if args.full else [])})
    out.append({"name": "gs-ibl-eevee", "engine": "eevee", "choice": "GSIBL", "samples": 1, "denoise": False,
                "sizes": [size]})
    return out


def display(img: np.ndarray, space: str) -> np.ndarray:
    """Blender's linear render as the capture's own values (what gsplat computes from its SH): sRGB-encoded for a
    capture in sRGB (Blender's Standard view), as it is for a linear one."""
    from gs_ibl_addon.core.colour import linear_to_srgb
    img = img.astype(np.float32).copy()
    if space == "srgb":
        img[..., :3] = linear_to_srgb(np.clip(img[..., :3], 0, None))
    return img


def load_refs(args) -> dict:
    """capture -> its refs npz (made here with --stand-in where the GPU machine's are missing)."""
    out = {}
    for name in [c for c in args.captures.split(",") if c]:
        path = os.path.join(args.refs, f"refs_{name}.npz")
        if not os.path.exists(path):
            if not args.stand_in:
                sys.exit(f"{path} is missing: run benchmarks/gpu_run.sh refs on the GPU machine and put its files "
                         "there, or pass --stand-in ours|numpy")
            local = os.path.join(ROOT, "out", "bench", "native_frame_refs")
            path = os.path.join(local, f"refs_{name}.npz")
            if not os.path.exists(path) or np.load(path)["size"].tolist() != list(args.size_wh):
                run_refs(argparse.Namespace(captures=name, views=args.views, size=args.size, fov=60.0,
                                            near=args.near, far=args.far, peer=args.stand_in, rounds=1,
                                            no_full=True, out=local))
        out[name] = dict(np.load(path))
        if out[name]["size"].tolist() != list(args.size_wh):
            sys.exit(f"{path} holds {out[name]['size'].tolist()} images, not {args.size}")
    return out


def run_bench(args) -> None:
    import fidelity_bench as fb
    from bench_common import append_csv
    from gs_ibl_addon.core.formats import read_scene
    from native_bench import _device
    sys.path.insert(0, os.path.join(ROOT, "tests", "real_blender"))
    import test_matrix as matrix
    matrix.TIMEOUT_S = 3 * 3600
    entry = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
    if not matrix._ready(entry.root):
        sys.exit(f"the bpy 5.3 root is not made: scripts/blender_roots.sh ensure {entry.root}")
    args.size_wh = tuple(fb.parse_size(args.size))
    refs = load_refs(args)
    device = _device()
    runner = matrix.Runner(entry, None)
    date = datetime.date.today().isoformat()
    try:
        zip_path = matrix.built_zip()
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        for f in (os.path.abspath(__file__), bs.__file__):
            shutil.copy(f, runner.host / os.path.basename(f))
        caps, spaces = [], {}
        for spec in [c for c in args.synthetic.split(",") if c]:  # time only: no reference image
            import frame_cost_bench as fcb
            from gs_ibl_addon.core.formats.ply import write_ply
            lab, scene, cv, _ = fcb.scene_and_camera(spec, *args.size_wh)
            name = lab.replace(" ", "_")
            write_ply(runner.host / f"{name}.ply", scene)
            spaces[name] = scene.colour_space
            caps.append({"name": name, "path": str(runner.inner / f"{name}.ply"), "views": [
                {"name": "v0", "camera": [*cv.matrix.ravel(), cv.tan_x, cv.tan_y, *cv.shift]}]})
        for name in [c for c in args.captures.split(",") if c]:
            _, path, _ = fb.parse_capture(name)
            shutil.copy(path, runner.host / os.path.basename(path))
            spaces[name] = read_scene(path).colour_space
            views = [{"name": v, "camera": refs[name][f"camera_{v}"].tolist()} for v in args.views.split(",")]
            caps.append({"name": name, "path": str(runner.inner / os.path.basename(path)), "views": views})
        job = {"work": str(runner.inner), "threads": args.threads, "near": args.near, "far": args.far,
               "size": list(args.size_wh), "captures": caps, "methods": methods(args)}
        (runner.host / "args.json").write_text(json.dumps(job))
        assert matrix._install(runner, str(runner.inner / "gs_ibl.zip")).returncode == 0, "install failed"
        log(f"Blender 5.3 (bpy, {args.threads} threads), {len(caps)} captures x {len(caps[-1]['views'])} views, "
            f"{len(job['methods'])} methods; load {os.getloadavg()[0]:.1f}")
        res = runner.run([runner.python(), str(runner.inner / "native_frame_bench.py"), "in-blender",
                          str(runner.inner / "args.json")], "bench")
        line = next((x for x in res.stdout.splitlines() if x.startswith(RESULT_TAG)), None)
        if line is None:
            sys.exit(f"no result (rc {res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}")
        result = json.loads(line[len(RESULT_TAG):])
        images = {}
        for p in runner.host.glob("*.npy"):
            images[p.stem] = np.load(p).astype(np.float32)
    finally:
        runner.close()
    rows = []
    for row in result["rows"]:
        ref = refs.get(row["capture"], {"reference": ""})
        img = images.get(f"{row['capture']}_{row['view']}_{row['method']}")
        small = (row["width"], row["height"]) == args.size_wh and img is not None and row["capture"] in refs
        shown = display(img, spaces[row["capture"]]) if small else None
        cmp = fb.compare(shown, ref[f"gsplat_{row['view']}"].astype(np.float32)) if small else {}
        lin = ref.get(f"gsplat_lin_{row['view']}")
        cmp_lin = fb.compare(shown, lin.astype(np.float32)) if small and lin is not None else {}
        rows.append({"date": date, "device": device, "blender": result["blender"],
                     "reference": str(ref["reference"]), **{k: v for k, v in row.items() if k != "messages"},
                     "psnr": cmp.get("psnr", ""), "psnr_alpha": cmp.get("psnr_alpha", ""),
                     "psnr_blender_rule": cmp_lin.get("psnr", ""),
                     "px_over_1pct": cmp.get("px_over_1pct", ""), "load": round(os.getloadavg()[0], 1)})
    if os.path.exists(args.csv):
        os.remove(args.csv)  # one run per file: the chart is of one run
    append_csv(args.csv, rows)
    with open(os.path.splitext(args.csv)[0] + ".json", "w") as f:
        json.dump({k: v for k, v in result.items() if k != "rows"}, f, indent=1)
    print_table(rows)
    plot(rows, args.png)
    if args.sheet:
        save_compare_sheet(args.sheet, rows, refs, images, spaces)
    log(f"wrote {args.csv}, {args.png}" + (f", {args.sheet}" if args.sheet else ""))


LABELS = {"native-cycles": "native Cycles", "native-eevee": "native EEVEE", "gs-ibl": "GS-IBL (F12, in Cycles)",
          "gs-ibl-eevee": "GS-IBL (F12, in EEVEE)"}


def label(row: dict) -> str:
    m = row["method"]
    if m.startswith("native-cycles"):
        return f"native Cycles {row['samples']} spp" + (" + OIDN" if str(row["denoise"]) == "True" else "")
    if m.startswith("native-eevee"):
        return f"native EEVEE {row['samples']} spp"
    return LABELS[m] + ("" if int(row["width"]) < FULL[0] else " 1920x1080")


def summary(rows: list[dict]) -> list[dict]:
    """Per capture and method: the median time per frame and PSNR over the views."""
    out = {}
    for r in rows:
        out.setdefault((r["capture"], label(r)), []).append(r)
    res = []
    for (cap, lab), rs in out.items():
        ps = [float(r["psnr"]) for r in rs if r["psnr"] != ""]
        pl = [float(r["psnr_blender_rule"]) for r in rs if r.get("psnr_blender_rule", "") != ""]
        res.append({"capture": cap, "method": lab, "views": len(rs), "width": rs[0]["width"],
                    "height": rs[0]["height"],
                    "render_s": statistics.median(float(r["render_s"]) for r in rs),
                    "splats_ms": statistics.median(float(r["splats_ms"]) for r in rs) if rs[0]["splats_ms"] != ""
                    else "", "psnr": statistics.median(ps) if ps else "", "psnr_min": min(ps) if ps else "",
                    "psnr_rule": statistics.median(pl) if pl else ""})
    return res


def print_table(rows: list[dict]) -> None:
    print("\n| capture | method | size | s per frame (median) | our splats' ms | PSNR dB (median, worst) | "
          "PSNR dB, Blender's colour rule |")
    print("|---|---|---|---:|---:|---:|---:|")
    for s in summary(rows):
        ps = f"{s['psnr']:.1f} ({s['psnr_min']:.1f})" if s["psnr"] != "" else "-"
        ms = f"{s['splats_ms']:.0f}" if s["splats_ms"] != "" else "-"
        rule = f"{s['psnr_rule']:.1f}" if s["psnr_rule"] != "" else "-"
        print(f"| {s['capture']} | {s['method']} | {s['width']}x{s['height']} | {s['render_s']:.2f} | {ms} | {ps} | "
              f"{rule} |")


def plot(rows: list[dict], png: str) -> None:
    """Per capture: each view's frames, time against PSNR (filled: against gsplat's image; hollow: against gsplat's
    splats blended by Blender's colour rule, for an sRGB capture); our 1920x1080 frame's time as a dotted line."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    caps = list(dict.fromkeys(r["capture"] for r in rows if r["psnr"] != ""))  # those with a reference
    if not caps:
        return
    views = list(dict.fromkeys(r["view"] for r in rows))
    shapes = dict(zip(views, "osD^v<>p"))
    fig, axes = plt.subplots(1, len(caps), figsize=(6.4 * len(caps), 5.0), squeeze=False)
    for ax, cap in zip(axes[0], caps):
        rs = [r for r in rows if r["capture"] == cap and r["psnr"] != ""]
        for r in rs:
            lab = label(r)
            colour = "tab:blue" if lab.startswith("GS-IBL") else ("tab:red" if "Cycles" in lab else "tab:green")
            t = float(r["render_s"])
            ax.scatter(t, float(r["psnr"]), color=colour, marker=shapes[r["view"]], s=36, zorder=3)
            if r.get("psnr_blender_rule", "") != "":
                ax.scatter(t, float(r["psnr_blender_rule"]), facecolors="none", edgecolors=colour,
                           marker=shapes[r["view"]], s=36, zorder=3)
            if r["view"] == views[0]:
                ax.annotate(lab, (t, float(r["psnr"])), textcoords="offset points", xytext=(5, 3), fontsize=6)
        lo = min(float(r["psnr"]) for r in rs)
        for r in rows:  # our 1920x1080 frames: time only (the references are at the comparison size)
            if r["capture"] == cap and r["psnr"] == "":
                ax.axvline(float(r["render_s"]), color="tab:blue", ls=":", lw=1)
                ax.text(float(r["render_s"]), lo, f" GS-IBL 1920x1080, {r['view']}", rotation=90, fontsize=6,
                        va="bottom", color="tab:blue")
        for v in views:
            ax.scatter([], [], color="grey", marker=shapes[v], label=f"view {v}")
        if any(r.get("psnr_blender_rule", "") != "" for r in rs):
            ax.scatter([], [], facecolors="none", edgecolors="grey", label="against gsplat by Blender's colour rule")
        ax.legend(fontsize=7, loc="best")
        ax.set_xscale("log")
        ax.set_xlabel(f"seconds per frame ({rs[0]['width']}x{rs[0]['height']} unless named)")
        ax.set_ylabel("PSNR against gsplat classic, dB")
        ax.set_title(cap, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    r0 = next(r for r in rows if r["capture"] in caps)
    fig.suptitle(f"A capture in F12: Blender {r0['blender']}'s native splats (red Cycles, green EEVEE) against GS-IBL "
                 f"drawing them (blue), {r0['device']}, load {r0.get('load', '?')} on 2 cores, {r0['date']};\n"
                 f"reference: {r0['reference']}", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(png, dpi=110)
    plt.close(fig)


def save_compare_sheet(path: str, rows: list[dict], refs: dict, images: dict, spaces: dict) -> None:
    """Per capture, its first view: the reference, each method's image (as compared) and its PSNR."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    caps = [c for c in dict.fromkeys(r["capture"] for r in rows) if c in refs]
    cols = list(dict.fromkeys(r["method"] for r in rows if r["psnr"] != ""))
    if not caps:
        return
    fig, axes = plt.subplots(len(caps), len(cols) + 1, figsize=(2.6 * (len(cols) + 1), 1.8 * len(caps) + 0.4),
                             squeeze=False)
    for i, cap in enumerate(caps):
        view = next(r["view"] for r in rows if r["capture"] == cap)
        axes[i][0].imshow(to_8bit(refs[cap][f"gsplat_{view}"].astype(np.float32)))
        axes[i][0].set_title(f"{cap} {view}: reference", fontsize=7)
        for j, m in enumerate(cols):
            row = next(r for r in rows if r["capture"] == cap and r["view"] == view and r["method"] == m
                       and r["psnr"] != "")
            axes[i][j + 1].imshow(to_8bit(display(images[f"{cap}_{view}_{m}"], spaces[cap])))
            axes[i][j + 1].set_title(f"{label(row)}\n{row['psnr']:.1f} dB, {float(row['render_s']):.1f} s",
                                     fontsize=7)
        for ax in axes[i]:
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def run_plot(args) -> None:
    import csv
    rows = list(csv.DictReader(open(args.csv)))
    print_table(rows)
    plot(rows, args.png)


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "in-blender":
        print(RESULT_TAG + json.dumps(_in_blender(json.load(open(argv[1])))), flush=True)
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["refs", "bench", "plot"])
    ap.add_argument("--captures", default="guitar,room")
    ap.add_argument("--synthetic", default="", help="bench: also frame_cost_bench's scenes (random:1M, shell:3M, ...), "
                    "their one view, time only (no reference image)")
    ap.add_argument("--views", default="", help="of v0..v7 (comma-separated; refs: empty is all eight; bench: "
                    "default v0,v4)")
    ap.add_argument("--size", default="480x270", help="the comparison size (native Cycles renders it on the CPU)")
    ap.add_argument("--fov", type=float, default=60.0)
    ap.add_argument("--near", type=float, default=0.1)
    ap.add_argument("--far", type=float, default=1000.0)
    ap.add_argument("--peer", choices=("auto", "gsplat", "numpy", "ours"), default="auto",
                    help="refs: gsplat on CUDA (auto falls back to the numpy port), the port, or ours")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-full", action="store_true", help="refs: skip the 1920x1080 times")
    ap.add_argument("--out", default=REFS_DIR, help="refs: where the references go")
    ap.add_argument("--refs", default=REFS_DIR, help="bench: the GPU machine's references")
    ap.add_argument("--stand-in", choices=("", "ours", "numpy"), default="",
                    help="bench: where a reference is missing, make it here (our image, or the numpy port)")
    ap.add_argument("--cycles-samples", type=lambda t: [int(x) for x in t.split(",") if x], default=[16])
    ap.add_argument("--denoise-samples", type=lambda t: [int(x) for x in t.split(",") if x], default=[16],
                    help="bench: Cycles sample counts also rendered with the OIDN denoiser")
    ap.add_argument("--eevee-samples", type=lambda t: [int(x) for x in t.split(",") if x], default=[1, 16])
    ap.add_argument("--no-full-frame", dest="full", action="store_false", help="bench: no 1920x1080 frame of ours")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--csv", default=None)
    ap.add_argument("--png", default=os.path.join(ROOT, "docs", "img", "native-frame-lavapipe.png"))
    ap.add_argument("--sheet", default=os.path.join(ROOT, "docs", "img", "native-frame-views-lavapipe.png"),
                    help="bench: the first view of each capture by every method (empty: none)")
    args = ap.parse_args(argv)
    if args.mode == "bench" and not args.views:
        args.views = "v0,v4"
    args.csv = args.csv or os.path.join(ROOT, "docs", "bench", "native_frame_lavapipe.csv")
    {"refs": run_refs, "bench": run_bench, "plot": run_plot}[args.mode](args)


if __name__ == "__main__":
    main()
