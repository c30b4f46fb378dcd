"""What one viewport-overlay redraw costs: one render of the splats at viewport size, as the overlay draws it.

Run: python benchmarks/overlay_bench.py [--sizes 960x540,1920x1080] [--scales 0.25,0.5,1.0] [--repeats 5]
Core only (no bpy): overlay_math turns a viewport's matrices into the render and the depth image into window
depth, exactly as the draw handler does. Scenes: the sample room (samples/room.ply, 22k splats, seen from inside)
and a 1M-splat synthetic scene (bench_common.bench_scene, a box of splats around the eye). Each row is the median
of --repeats renders of a view that changed since the last one (a new view: what orbiting costs per frame), with
wall time (host: submit, wait, read back colour and depth as the draw handler does; exposure, the sRGB curve and
window depth are applied by the overlay's shader) and GPU time (timestamps). Blender's texture upload is not
included (measured separately: 24 ms for a 1920x1080 RGBA32F texture on llvmpipe).
Prints a markdown table and appends rows to out/bench/overlay.csv (copy it into docs/bench/ to publish a run).
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_common import append_csv, bench_scene, gpu_clock, hold_gpu_clock, warm_up  # noqa: E402

from gs_ibl_addon.blender.viewport.overlay_math import look_at_view_matrix, overlay_view, perspective_matrix  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
FOV = 50.0  # Blender's default viewport lens (50 mm on a 36 mm sensor) is about 40 degrees; wider is harder


def _views(eye, target, n: int) -> list:
    """n view matrices orbiting a little around ``target`` (each render sees a new view, as while orbiting)."""
    eye, target = [float(x) for x in eye], [float(x) for x in target]
    dx, dy = eye[0] - target[0], eye[1] - target[1]
    r, a0 = math.hypot(dx, dy), math.atan2(dy, dx)
    return [look_at_view_matrix((target[0] + r * math.cos(a0 + 0.02 * k), target[1] + r * math.sin(a0 + 0.02 * k),
                                 eye[2]), target) for k in range(n)]


def redraw(renderer: SplatRenderer, view, window, width: int, height: int, scale: float) -> tuple[float, float]:
    """One overlay redraw of a new view: (wall ms, GPU ms)."""
    t = time.perf_counter()
    ov = overlay_view(view, window, width, height, scale)
    res = renderer.render(ov.batch, timestamps=True, depth=True)
    np.ascontiguousarray(res.images[0][::-1])  # read back, in the rows the GPU texture takes (overlay_gpu._float_texture)
    np.ascontiguousarray(res.depths[0][::-1])
    return (time.perf_counter() - t) * 1e3, res.timings_ms.get("total", float("nan"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="960x540,1920x1080", help="viewport region sizes WxH")
    ap.add_argument("--scales", default="0.25,0.5,1.0", help="Resolution settings (fraction of the region)")
    ap.add_argument("--scenes", default="room,synthetic1m")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--csv", default=os.path.join(REPO, "out", "bench", "overlay.csv"))
    ap.add_argument("--hold-clock", action="store_true",
                    help="hold an NVIDIA GPU's SM clock with a CUDA context in this process (torch), as Blender's "
                         "own drawing keeps the GPU busy; the clock is recorded either way")
    args = ap.parse_args()
    holder = hold_gpu_clock() if args.hold_clock else None  # noqa: F841  kept alive for the whole run
    ctx = get_context()
    date = datetime.date.today().isoformat()
    print(f"device: {ctx.device_name}, date {date}, median of {args.repeats} new views")
    print("| scene | splats | viewport | scale | rendered px | wall ms | GPU ms |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for name in args.scenes.split(","):
        if name == "room":
            scene = read_scene(os.path.join(REPO, "samples", "room.ply"))
            eye, target = (0.2, -2.1, 1.45), (0.35, 1.2, 0.75)  # inside the room, as a user looks around it
        elif name == "synthetic1m":
            scene = bench_scene(1_000_000)
            eye, target = (0.0, -3.0, 0.5), (0.0, 0.0, 0.0)  # inside the 5-unit box of splats
        else:
            raise SystemExit(f"--scenes: unknown scene '{name}' (room, synthetic1m)")
        t = time.perf_counter()
        renderer = SplatRenderer(scene)
        upload_s = time.perf_counter() - t
        for size in args.sizes.split(","):
            w, h = (int(x) for x in size.lower().split("x"))
            window = perspective_matrix(FOV, w, h, near=0.1, far=100.0)
            for scale in (float(s) for s in args.scales.split(",")):
                views = _views(eye, target, args.repeats + 8)
                it = iter(views)
                warm_up(lambda: redraw(renderer, next(it, views[0]), window, w, h, scale), seconds=0.5)
                runs = [redraw(renderer, v, window, w, h, scale) for v in views[-args.repeats:]]
                wall = statistics.median(r[0] for r in runs)
                gpu = statistics.median(r[1] for r in runs)
                px = f"{max(1, round(w * scale))}x{max(1, round(h * scale))}"
                clock = gpu_clock()
                print(f"| {name} | {scene.count:,} | {w}x{h} | {scale} | {px} | {wall:.1f} | {gpu:.1f} |"
                      + (f" {clock} MHz" if clock else ""))
                rows.append({"device": ctx.device_name, "date": date, "sm_clock_mhz": clock, "scene": name,
                             "splats": scene.count,
                             "width": w, "height": h, "scale": scale, "wall_ms": round(wall, 2),
                             "gpu_ms": round(gpu, 2), "upload_s": round(upload_s, 2), "repeats": args.repeats})
        renderer.close()
    append_csv(args.csv, rows)
    print(f"appended {len(rows)} rows to {os.path.abspath(args.csv)}")


if __name__ == "__main__":
    main()
