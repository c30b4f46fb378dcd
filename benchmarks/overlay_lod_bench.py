"""The viewport overlay while the view moves: frames/s of an orbit with the full scene (the overlay before the motion
copy) and with the motion copy (overlay_math.SplatOverlay, core/render/coarse.py), the still frame, and what the
moving frame costs in image error against the still frame of the same view.

Run: python benchmarks/overlay_lod_bench.py [--counts 1000000,3000000] [--size 1311x878] [--budgets 100000]
     [--frames 10] [--csv docs/bench/overlay_lod_<device>.csv] [--png docs/overlay-lod.png] [--hold-clock]

Core only (no bpy), so it runs as it is on a GPU machine. Scene: bench_common.bench_scene (a 5-unit box of splats,
SH degree 3, seen from inside it, as overlay_bench.py). The overlay's renderer holds the full scene (as
splat_cache's does) and the copy is built from its base colour only (splat_cache's host copy, what the draw
handler passes). Per frame, as the draw handler does: SplatOverlay.image of a new view of an orbit (1.15 degrees
a frame), colour and depth read back and flipped into texture rows. Rows:
  moving-full    the full scene at MOVING_SCALE (what the overlay drew while moving before this)
  moving-coarse  the motion copy at MOVING_SCALE (image(..., moving=True))
  still          the full scene at the default Resolution (0.5)
wall and GPU ms are medians over the frames; frames/s = 1000 / wall. Error: the moving frame against the still
frame of the same view, both stretched to the region bilinearly (as the overlay's texture is drawn), composited
over Blender's default viewport grey and sRGB-encoded as the screen shows it: mean absolute error in 8-bit levels,
per pixel (``mae``) and after a 16x16-pixel block mean (``mae_16px``: the picture's shapes and colours rather than
its grain). The copy's build (grid merge + its octree, numpy, on the overlay's worker thread) and, with
--full-tree, the octree of the whole scene (render/lod.py, for comparison) are timed. The load average
(os.getloadavg, 1 minute) is recorded with every row: other jobs share this 2-core machine.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_common import append_csv, bench_scene, gpu_clock, hold_gpu_clock  # noqa: E402

from gs_ibl_addon.blender.viewport import overlay_math as om  # noqa: E402
from gs_ibl_addon.core.colour import linear_to_srgb  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
FOV = 50.0
STILL_SCALE = 0.5  # the Resolution setting's default
BACKGROUND = 0.0467  # Blender's default Solid-mode viewport grey (#3D3D3D), linear
EYE, TARGET = (0.0, -3.0, 0.5), (0.0, 0.0, 0.0)
STEP = 0.02  # radians of orbit per frame


def orbit(k: int) -> np.ndarray:
    r, a0 = math.hypot(EYE[0] - TARGET[0], EYE[1] - TARGET[1]), math.atan2(EYE[1] - TARGET[1], EYE[0] - TARGET[0])
    a = a0 + STEP * k
    return om.look_at_view_matrix((TARGET[0] + r * math.cos(a), TARGET[1] + r * math.sin(a), EYE[2]), TARGET)


def draw(ov: om.SplatOverlay, view, window, w: int, h: int, scale: float, moving: bool, slot) -> tuple:
    """One redraw as the handler makes it: (image, wall ms)."""
    t = time.perf_counter()
    img = ov.image(view, window, w, h, scale, slot=slot, moving=moving)
    np.ascontiguousarray(img.rgba[::-1])  # the rows the GPU texture takes (overlay_gpu._float_texture)
    np.ascontiguousarray(img.depth[::-1])
    return img, (time.perf_counter() - t) * 1e3


def stretch(rgba: np.ndarray, w: int, h: int) -> np.ndarray:
    """Bilinear resize to (h, w), pixel centres aligned, edges clamped: the quad's linear texture filter."""
    ih, iw = rgba.shape[:2]

    def axis(n_out, n_in):
        x = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
        x0 = np.clip(np.floor(x).astype(int), 0, n_in - 1)
        x1 = np.clip(x0 + 1, 0, n_in - 1)
        return x0, x1, np.clip(x - np.floor(x), 0, 1)
    y0, y1, fy = axis(h, ih)
    x0, x1, fx = axis(w, iw)
    a = rgba[y0][:, x0] * (1 - fx)[None, :, None] + rgba[y0][:, x1] * fx[None, :, None]
    b = rgba[y1][:, x0] * (1 - fx)[None, :, None] + rgba[y1][:, x1] * fx[None, :, None]
    return a * (1 - fy)[:, None, None] + b * fy[:, None, None]


def screen(rgba: np.ndarray, w: int, h: int) -> np.ndarray:
    """What the viewport shows: premultiplied linear RGBA over the grey background, sRGB, 8-bit levels."""
    s = stretch(np.asarray(rgba, np.float64), w, h)
    lin = s[..., :3] + (1.0 - s[..., 3:4]) * BACKGROUND
    return linear_to_srgb(np.clip(lin, 0.0, 1.0)) * 255.0


def errors(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    h, w = a.shape[0] // 16 * 16, a.shape[1] // 16 * 16
    block = lambda x: x[:h, :w].reshape(h // 16, 16, w // 16, 16, 3).mean((1, 3))  # noqa: E731
    return float(np.abs(a - b).mean()), float(np.abs(block(a) - block(b)).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", default="1000000,3000000")
    ap.add_argument("--size", default="1311x878", help="viewport region WxH")
    ap.add_argument("--budgets", default=str(om.MOTION_BUDGET), help="motion copy sizes (splats)")
    ap.add_argument("--moving-scales", default=str(om.MOVING_SCALE))
    ap.add_argument("--copy-resolutions", default=str(om.MOTION_RESOLUTION),
                    help="the copy's resolution as a fraction of the moving scale (SplatOverlay.motion_resolution)")
    ap.add_argument("--frames", type=int, default=10, help="orbit frames per moving-coarse row")
    ap.add_argument("--full-frames", type=int, default=3, help="orbit frames per moving-full and still row")
    ap.add_argument("--error-views", type=int, default=2, help="views whose moving frames are compared with still")
    ap.add_argument("--full-tree", action="store_true", help="also time render/lod.py's octree of the whole scene")
    ap.add_argument("--csv", default=None, help="default docs/bench/overlay_lod_<device>.csv")
    ap.add_argument("--png", default=None, help="a chart and the images of the last scene")
    ap.add_argument("--hold-clock", action="store_true")
    args = ap.parse_args()
    holder = hold_gpu_clock() if args.hold_clock else None  # noqa: F841
    ctx = get_context()
    device = "lavapipe" if "llvmpipe" in ctx.device_name.lower() else ctx.device_name.lower().replace(" ", "-")
    csv = args.csv or os.path.join(REPO, "docs", "bench", f"overlay_lod_{device}.csv")
    w, h = (int(x) for x in args.size.lower().split("x"))
    window = om.perspective_matrix(FOV, w, h, near=0.1, far=100.0)
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    print(f"device: {ctx.device_name}, {date} UTC, region {w}x{h}, still at Resolution {STILL_SCALE}")
    print("| splats | mode | copy | scale | wall ms | GPU ms | frames/s | mae (8-bit) | mae 16px | build s | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows, pictures = [], {}

    def row(n, mode, budget, copy_n, scale, walls, gpus, err, build_s, tree_s=None):
        wall, gpu = statistics.median(walls), statistics.median(gpus)
        load = os.getloadavg()[0]
        clock = gpu_clock()
        e = (statistics.mean(x[0] for x in err), statistics.mean(x[1] for x in err)) if err else (math.nan,) * 2
        print(f"| {n:,} | {mode} | {copy_n or '-'} | {scale} | {wall:.0f} | {gpu:.0f} | {1e3 / wall:.2f} | "
              f"{e[0]:.1f} | {e[1]:.1f} | {build_s if build_s is not None else '-'} | {load:.2f} |")
        rows.append({"device": ctx.device_name, "date": date, "sm_clock_mhz": clock, "splats": n, "mode": mode,
                     "budget": budget, "copy_splats": copy_n, "width": w, "height": h, "scale": scale,
                     "wall_ms": round(wall, 1), "gpu_ms": round(gpu, 1), "fps": round(1e3 / wall, 2),
                     "frames": len(walls), "mae8": round(e[0], 2), "mae8_16px": round(e[1], 2),
                     "build_s": build_s, "full_tree_s": tree_s, "load1": round(load, 2)})

    for n in (int(x) for x in args.counts.split(",")):
        scene = bench_scene(n)
        slim = replace(scene, sh=scene.sh[:, :1].copy())  # splat_cache's host copy
        tree_s = None
        if args.full_tree:
            from gs_ibl_addon.core.render.lod import build_lod
            t = time.perf_counter()
            build_lod(scene)
            tree_s = round(time.perf_counter() - t, 2)
            print(f"render/lod.py octree of all {n:,} splats: {tree_s} s")
        renderer = SplatRenderer(scene)
        still_imgs = {}
        base = om.SplatOverlay(renderer=renderer)
        base.timestamps = True
        walls, gpus = [], []
        for k in range(args.full_frames):  # still: a new view each time at the still scale, full detail
            img, ms = draw(base, orbit(k), window, w, h, STILL_SCALE, False, "still")
            walls.append(ms)
            gpus.append(img.gpu_ms)
            still_imgs[k] = screen(img.rgba, w, h)
        row(n, "still", 0, 0, STILL_SCALE, walls, gpus, [], None, tree_s)
        for scale in (float(s) for s in args.moving_scales.split(",")):
            walls, gpus, err = [], [], []
            for k in range(args.full_frames):  # the overlay before the motion copy: full detail, lower resolution
                img, ms = draw(base, orbit(k), window, w, h, scale, True, "moving")
                walls.append(ms)
                gpus.append(img.gpu_ms)
                if k < args.error_views:
                    shown = screen(img.rgba, w, h)
                    err.append(errors(shown, still_imgs[k]))
                    if k == 0:
                        pictures[(n, "moving-full", scale)] = shown
            row(n, "moving-full", 0, 0, scale, walls, gpus, err, None)
            for budget, copy_res in ((int(b), float(c)) for b in args.budgets.split(",")
                                     for c in args.copy_resolutions.split(",")):
                ov = om.SplatOverlay(renderer=renderer, motion_scene=slim, motion_budget=budget)
                ov.timestamps = True
                ov.motion_resolution = copy_res
                draw(ov, orbit(0), window, w, h, STILL_SCALE, False, "r")  # the first sight: still, full detail
                if ov.motion is None:  # the full scene keeps up (a GPU): nothing to measure for the copy
                    print(f"  {n:,} splats: the full scene drew in {ov.full_ms:.1f} ms, within a frame: no copy")
                    ov.close()
                    continue
                ov.motion.wait()
                build_s = round(ov.motion.build_s, 2)
                walls, gpus, err = [], [], []
                first = True
                for k in range(1, args.frames + 2):
                    img, ms = draw(ov, orbit(k), window, w, h, scale, True, "r")
                    if first:  # the first coarse frame also uploads the copy (once per object version)
                        first = False
                        print(f"  first moving frame (uploads the {ov.motion.coarse.scene.count:,}-splat copy): "
                              f"{ms:.0f} ms")
                        continue
                    walls.append(ms)
                    gpus.append(img.gpu_ms)
                    assert img.coarse
                for k in range(args.error_views):
                    img, _ = draw(ov, orbit(k), window, w, h, scale, True, "err")
                    shown = screen(img.rgba, w, h)
                    err.append(errors(shown, still_imgs[k]))
                    if k == 0:
                        pictures[(n, f"moving-coarse {budget}", img.scale)] = shown
                row(n, "moving-coarse", budget, ov.motion.coarse.scene.count, img.scale, walls, gpus, err, build_s)
                ov.close()
        pictures[(n, "still", STILL_SCALE)] = still_imgs[0]
        base.close()
        renderer.close()
        del scene, slim
    append_csv(csv, rows)
    print(f"appended {len(rows)} rows to {os.path.abspath(csv)}")
    if args.png:
        plot(rows, pictures, args.png, ctx.device_name, date)


def plot(rows: list[dict], pictures: dict, path: str, device: str, date: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    counts = sorted({r["splats"] for r in rows})
    modes = [("still", "still (Resolution 0.5)", "#888888"), ("moving-full", "moving, full scene", "#d62728"),
             ("moving-coarse", "moving, motion copy", "#2ca02c")]
    n_last = counts[-1]
    pics = [(k, v) for k, v in pictures.items() if k[0] == n_last]
    fig = plt.figure(figsize=(13, 7.0))
    gs = fig.add_gridspec(2, max(3, len(pics)), height_ratios=[1, 0.75])
    ax = fig.add_subplot(gs[0, :2])
    width = 0.8 / len(modes)
    for i, (mode, label, colour) in enumerate(modes):
        vals = []
        for n in counts:
            sel = [r for r in rows if r["splats"] == n and r["mode"] == mode]
            vals.append(max((r["fps"] for r in sel), default=0))
        xs = np.arange(len(counts)) + (i - 1) * width
        bars = ax.bar(xs, vals, width, label=label, color=colour)
        ax.bar_label(bars, fmt="%.2f", fontsize=8)
    ax.set_title("best row of each mode", fontsize=9)
    ax.axhline(5, color="k", ls="--", lw=0.8)
    ax.text(len(counts) - 0.55, 5.2, "target 5 frames/s", fontsize=8, ha="right")
    ax.set_xticks(np.arange(len(counts)), [f"{n / 1e6:g}M splats" for n in counts])
    ax.set_ylabel("frames/s (core: render + read-back)")
    fig.suptitle(f"Overlay orbit at {rows[0]['width']}x{rows[0]['height']} (bench_scene, eye inside it), {device}, "
                 f"{date} UTC, load {min(r['load1'] for r in rows):.1f}-{max(r['load1'] for r in rows):.1f}; "
                 f"images: the middle of the screen, {n_last / 1e6:g}M", fontsize=10)
    ax.legend(fontsize=8)
    ax2 = fig.add_subplot(gs[0, 2:])
    for mode, label, colour in modes[1:]:
        sel = [r for r in rows if r["mode"] == mode]
        ax2.plot([r["splats"] / 1e6 for r in sel], [r["mae8"] for r in sel], "o-", color=colour, label=f"{label}")
        ax2.plot([r["splats"] / 1e6 for r in sel], [r["mae8_16px"] for r in sel], "s--", color=colour,
                 label=f"{label}, 16 px blocks")
    ax2.set_xlabel("million splats")
    ax2.set_ylabel("mean abs error vs still (8-bit levels)")
    ax2.set_ylim(bottom=0)
    ax2.legend(fontsize=7)
    for j, ((n, mode, scale), img) in enumerate(pics):
        a = fig.add_subplot(gs[1, j])
        hh, ww = img.shape[:2]
        a.imshow(np.clip(img[hh // 4:3 * hh // 4, ww // 4:3 * ww // 4] / 255.0, 0, 1), interpolation="nearest")
        a.set_title(f"{n / 1e6:g}M: {mode} (x{scale})", fontsize=9)
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {os.path.abspath(path)}")


if __name__ == "__main__":
    main()
