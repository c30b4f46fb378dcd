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
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

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

    def __init__(self, ours) -> None:
        self.ours = ours

    def render(self, cv) -> np.ndarray:
        return self.ours.render(cv)


def make_reference(kind: str, scene, near: float, far: float, ours):
    """gsplat on CUDA (auto, gsplat), else the numpy port (numpy) or our own image (ours)."""
    import fidelity_bench as fb
    if kind == "ours":
        return StandIn(ours)
    if kind == "numpy":
        return fb.ClassicNumpy(scene, near, far)
    return fb.make_peer(kind, scene, near, far)


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
        del ref
    log(f"wrote {args.out}")


def save_sheet(path: str, title: str, arrays: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    views = sorted(k.split("_", 1)[1] for k in arrays if k.startswith("gsplat_"))
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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["refs"])
    ap.add_argument("--captures", default="guitar,room")
    ap.add_argument("--views", default="", help="of v0..v7 (comma-separated; empty: all eight)")
    ap.add_argument("--size", default="480x270", help="the comparison size (native Cycles renders it on the CPU)")
    ap.add_argument("--fov", type=float, default=60.0)
    ap.add_argument("--near", type=float, default=0.1)
    ap.add_argument("--far", type=float, default=1000.0)
    ap.add_argument("--peer", choices=("auto", "gsplat", "numpy", "ours"), default="auto",
                    help="the reference: gsplat on CUDA (auto falls back to the numpy port), the port, or ours")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-full", action="store_true", help="skip the 1920x1080 times")
    ap.add_argument("--out", default=REFS_DIR)
    args = ap.parse_args(argv)
    {"refs": run_refs}[args.mode](args)


if __name__ == "__main__":
    main()
