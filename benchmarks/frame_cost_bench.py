"""What a final render's frame costs (issue 36, item 5): the splats of one 1920x1080 camera frame drawn the way F12
draws them, with a depth cut (FRONT/BEHIND) and without, per stage, GPU and wall, beside gsplat 1.5.3's time for
the same frame (classic mode, the same camera), one process, one GPU.

The frame (blender/render/frame.py _draw): the meshes' planar depth per pixel (core/render/mesh_depth.py, on the
CPU; here a UV sphere of 32x16 quads standing in the view, the far clip where no mesh is), then
``SplatRenderer.render_camera(ViewBatch.camera(...), cut=...)`` (render(cut=...) and the two layers read back;
render() and its images where the core has no render_camera), BEHIND kept where a mesh is. Without a cut: the same
call with ``cut=None``. Rows per scene and renderer: the median GPU time (timestamp queries; gsplat: CUDA events)
and per stage (ours: clear, preprocess, sort_depth, emit, sort_tiles, ranges, raster; gsplat: its kernels by the
same names, torch profiler, where ``--gsplat-stages``), the wall time in parts (mesh_depth; splats: our renderer's
call with the layers read back, or gsplat's call, synchronize and its images read back; post: BEHIND masked where no
mesh is) and whole, the SM clock before and after the blocks (NVML), the (tile, splat) pairs drawn. Renderers are
warmed up, then timed in interleaved blocks, as peer_bench does.

Scenes: ``room`` (samples/room.ply), ``guitar`` (tests/data/guitar.compressed.ply) from fidelity_bench's view v4
(1.25 dense-core radii out: the capture fills the frame), and peer_bench's synthetic ones, ``random:N`` (bench_scene:
a box of splats about the camera) and ``shell:N`` (a shell of radius 5-6 about it), from the origin along +X, 60°
across (N may end in k or M).

  python benchmarks/frame_cost_bench.py bench [--scenes room,guitar,random:1M,random:3M,shell:1M,shell:3M]
         [--size 1920x1080] [--csv out/bench/frame_cost.csv] [--gsplat-stages] [--deadline SECONDS]
  python benchmarks/frame_cost_bench.py plot --csv out/bench/frame_cost.csv --png docs/final-frame-cost.png
"""
from __future__ import annotations

import argparse
import csv
import datetime
import math
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from bench_common import append_csv, bench_scene, gpu_clock, hold_gpu_clock, shell_scene  # noqa: E402

STAGES = ("clear", "preprocess", "sort_depth", "emit", "sort_tiles", "ranges", "raster")
WALL_PARTS = ("mesh_depth", "splats", "post")
WALL_LABELS = {"mesh_depth": "wall: mesh depth (CPU)", "splats": "wall: splats drawn and read back",
               "post": "wall: BEHIND masked"}
FOV = 60.0
CLIP_END = 1000.0
NEAR = 0.1
T0 = time.perf_counter()


def log(*a) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s]", *a, flush=True)


def count(s: str) -> int:
    s = s.strip().lower()
    mult = {"k": 1_000, "m": 1_000_000}.get(s[-1], 1)
    return int(float(s[:-1] if mult > 1 else s) * mult)


def uv_sphere(centre, radius: float, nu: int = 32, nv: int = 16) -> np.ndarray:
    """(2 nu nv, 3, 3) world-space triangles of a UV sphere."""
    th = np.linspace(0, np.pi, nv + 1)
    ph = np.linspace(0, 2 * np.pi, nu + 1)
    p = np.stack([np.sin(th)[:, None] * np.cos(ph)[None], np.sin(th)[:, None] * np.sin(ph)[None],
                  np.cos(th)[:, None] * np.ones_like(ph)[None]], -1) * radius + np.asarray(centre, np.float64)
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def scene_and_camera(spec: str, width: int, height: int):
    """(label, scene, fidelity_bench.CameraView, mesh triangles) of a --scenes entry: the colour rule off, the
    sphere on the view axis at 60% of the median depth of the splats ahead, a quarter of the frame's height wide."""
    import fidelity_bench as fb
    kind, _, n = spec.partition(":")
    if kind in fb.CAPTURES:
        name, path, up = fb.parse_capture(kind)
        scene = fb.load_capture(path)
        cv = fb.camera_views(scene, up, width, height, FOV)[4]
        label = kind
    else:
        scene = {"random": lambda k: bench_scene(k, 3, 5.0), "shell": shell_scene}[kind](count(n))
        scene.colour_space = "linear"
        tx = math.tan(math.radians(FOV) / 2)
        cv = fb.CameraView("origin+x", fb.look_at(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
                           tx, tx * height / width, width, height, (0.0, 0.0))
        label = f"{kind} {scene.count / 1e6:g}M"
    f = -cv.matrix[:3, 2]
    z = (scene.positions.astype(np.float64) - cv.matrix[:3, 3]) @ f
    depth = float(np.median(z[z > NEAR])) if (z > NEAR).any() else 1.0
    tris = uv_sphere(cv.matrix[:3, 3] + 0.6 * depth * f, 0.6 * depth * cv.tan_y * 0.5)
    return label, scene, cv, tris


class Ours:
    """The F12 frame (cut=True: mesh depth, the splats with the cut, FRONT and BEHIND back on the host, BEHIND kept
    where a mesh is) or the same frame without a cut. The splats as F12 draws them (blender/render/splats.py
    render_layers): SplatRenderer.render_camera (render(cut=...) and the layers read back) where the core has it."""

    def __init__(self, renderer, cv, tris, cut: bool) -> None:
        import fidelity_bench as fb
        self.r, self.cv, self.tris, self.cut = renderer, cv, tris, cut
        self.batch = fb.our_batch(cv)
        self.name = "gs-ibl cut" if cut else "gs-ibl"
        self.mesh_share = 0.0

    def splats(self, cut) -> tuple[np.ndarray, np.ndarray, dict]:
        if hasattr(self.r, "render_camera"):
            f = self.r.render_camera(self.batch, cut=cut, depth=False, timestamps=True)
            return f.front, f.behind, f.timings
        res = self.r.render(self.batch, timestamps=True, cut=cut)
        front = res.images[0]
        return front, res.behinds[0] if cut is not None else np.zeros_like(front), res.timings_ms

    def rep(self) -> dict:
        from gs_ibl_addon.core.render.mesh_depth import mesh_depth
        cv = self.cv
        t0 = time.perf_counter()
        cut = no_mesh = None
        if self.cut:
            z = mesh_depth(self.tris, cv.matrix, cv.tan_x, cv.tan_y, cv.width, cv.height, cv.shift[0], cv.shift[1],
                           near=NEAR, far=CLIP_END)
            no_mesh = ~np.isfinite(z)
            self.mesh_share = 1.0 - float(no_mesh.mean())
            cut = np.where(no_mesh, np.float32(CLIP_END), z).astype(np.float32)
        t1 = time.perf_counter()
        front, behind, t = self.splats(cut)
        t2 = time.perf_counter()
        if self.cut:  # frame.py _draw: BEHIND only where a mesh is
            behind = np.where(no_mesh[..., None], 0.0, behind).astype(np.float32)
        t3 = time.perf_counter()
        self.last = (front, behind)
        try:
            pairs = int(self.r.count.read(np.uint32, 1)[0])  # the pairs the raster drew (peer_bench.drawn_pairs)
        except Exception:  # noqa: BLE001 - a renderer without that buffer
            pairs = ""
        out = {"gpu_ms": t["total"], "mesh_depth": (t1 - t0) * 1e3, "splats": (t2 - t1) * 1e3,
               "post": (t3 - t2) * 1e3, "wall_ms": (t3 - t0) * 1e3, "pairs": pairs}
        for st in STAGES:
            out[st] = t.get(st, 0.0) + sum(v for k, v in t.items() if k.startswith(st + "."))
        return out


def gsplat_peer(scene, cv):
    """peer_bench.Gsplat drawing ``cv`` (fidelity_bench.opencv_camera: lens shift included) in classic mode at the
    scene's SH degree; its wall time includes the image read back to the host, as ours does."""
    import fidelity_bench as fb
    from peer_bench import Gsplat

    class Frame(Gsplat):
        name = "gsplat"
        readback = True

        def __init__(self) -> None:
            super().__init__(scene)
            tt = lambda a: self.torch.tensor(np.array(a)[None], dtype=self.torch.float32, device="cuda")  # noqa: E731
            vm, k = fb.opencv_camera(cv)
            self.vm, self.k, self.size, self.mode, self.mirror = tt(vm), tt(k), (cv.width, cv.height), "classic", False
            self.deg = int(round(math.sqrt(scene.sh.shape[1]))) - 1

        def call(self):
            return self.raster(*self.t, self.vm, self.k, *self.size, sh_degree=self.deg, near_plane=NEAR,
                               far_plane=CLIP_END, rasterize_mode="classic", packed=True)

        def rep(self) -> dict:
            r = super().rep()
            return {"gpu_ms": r["gpu_ms"], "mesh_depth": 0.0, "splats": r["wall_ms"], "post": 0.0,
                    "wall_ms": r["wall_ms"], "pairs": r["pairs"]}

    return Frame()


def run_bench(args) -> None:
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    from gs_ibl_addon.core.vk import get_context
    from peer_bench import Nvml, gsplat_stages, load_gsplat
    hold = hold_gpu_clock()  # noqa: F841 - the CUDA context holds the SM clock (shared/NOTES-vulkan-and-gpu.md)
    nv = Nvml()
    info = nv.info()
    have_gsplat = False
    if not args.no_gsplat:
        try:
            t = time.perf_counter()
            g = load_gsplat()
            have_gsplat = True
            log(f"gsplat {g.__version__} ready in {time.perf_counter() - t:.1f} s")
        except Exception as e:  # noqa: BLE001 - no torch / CUDA here: our rows only
            log(f"no gsplat ({type(e).__name__}: {e}): our rows only")
    ctx = get_context()
    log(f"device {ctx.device_name}, NVML {info}")
    w, h = (int(x) for x in args.size.lower().split("x"))
    date = datetime.date.today().isoformat()
    deadline = T0 + args.deadline if args.deadline else None
    for spec in [s for s in args.scenes.split(",") if s]:
        if deadline and time.perf_counter() > deadline:
            log(f"past --deadline {args.deadline:.0f} s: {spec} left out")
            continue
        t = time.perf_counter()
        label, scene, cv, tris = scene_and_camera(spec, w, h)
        r = SplatRenderer(scene, ctx, near=NEAR)
        rends = [Ours(r, cv, tris, False), Ours(r, cv, tris, True)]
        if have_gsplat:
            rends.append(gsplat_peer(scene, cv))
        log(f"{label}: {scene.count:,} splats, scene and uploads {time.perf_counter() - t:.1f} s")
        for x in rends:  # warm-up: pipelines, buffers sized by the first frames
            t = time.perf_counter()
            x.rep()
            while time.perf_counter() - t < args.warmup:
                x.rep()
        reps = {x.name: [] for x in rends}
        clocks = {x.name: [] for x in rends}
        for _ in range(args.rounds):
            for x in rends:
                c0 = gpu_clock()
                reps[x.name] += [x.rep() for _ in range(args.block)]
                clocks[x.name] += [c for c in (c0, gpu_clock()) if c != ""]
        mesh_share = rends[1].mesh_share
        peer_stages = None
        if have_gsplat and args.gsplat_stages:
            peer_stages = gsplat_stages(rends[-1].kernel_ms())
        rows = []
        for x in rends:
            rp = reps[x.name]
            med = lambda k, rp=rp: round(statistics.median(q[k] for q in rp), 4)  # noqa: E731
            row = {"device": ctx.device_name, "driver": info.get("driver", ""), "date": date, "scene": label,
                   "splats": scene.count, "width": w, "height": h, "renderer": x.name, "gpu_ms": med("gpu_ms"),
                   "gpu_min_ms": round(min(q["gpu_ms"] for q in rp), 4), "wall_ms": med("wall_ms"),
                   **{f"{p}_ms": med(p) for p in WALL_PARTS}, "pairs": rp[-1]["pairs"],
                   "sm_mhz_min": min(clocks[x.name], default=""), "sm_mhz_max": max(clocks[x.name], default=""),
                   "reps": len(rp), "mesh_share": round(mesh_share, 4) if x.name == "gs-ibl cut" else ""}
            if x.name.startswith("gs-ibl"):
                row.update({f"{s}_ms": med(s) for s in STAGES})
                row["other_ms"] = ""
            else:
                row.update({f"{s}_ms": round(peer_stages.get(s, 0.0), 4) if peer_stages else "" for s in STAGES})
                row["other_ms"] = round(peer_stages["other"], 4) if peer_stages else ""
            rows.append(row)
        append_csv(args.csv, rows)
        cut_rows = rows[1]
        log(f"{label} {w}x{h}: " + " | ".join(
            f"{q['renderer']} GPU {q['gpu_ms']:.2f} ms, wall {q['wall_ms']:.1f} (mesh depth {q['mesh_depth_ms']:.1f}, "
            f"splats {q['splats_ms']:.1f}, post {q['post_ms']:.1f})" for q in rows)
            + f" | SM {cut_rows['sm_mhz_min']}-{cut_rows['sm_mhz_max']} MHz | "
            + " ".join(f"{s} {cut_rows[s + '_ms']:.2f}" for s in STAGES) + f" | mesh on {100 * mesh_share:.0f}%")
        r.close()
        del rends
        if have_gsplat:
            import torch
            torch.cuda.empty_cache()


def run_plot(args) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with open(args.csv) as f:
        rows = list(csv.DictReader(f))
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(max(8.0, 3.3 * len(scenes) + 1), 5.0), squeeze=False)
    colours = dict(zip(STAGES, plt.cm.tab10.colors))
    wall_col = {"mesh_depth": "#999999", "splats": "#5577aa", "post": "#bb8844"}
    for ax, sc in zip(axes[0], scenes):
        rs = [r for r in rows if r["scene"] == sc]
        names = [r["renderer"] for r in rs]
        for i, r in enumerate(rs):
            x = 2.4 * i
            bottom = 0.0
            staged = r.get("preprocess_ms", "") != ""
            if staged:
                for s in STAGES:
                    v = float(r[s + "_ms"] or 0)
                    ax.bar(x, v, 0.9, bottom=bottom, color=colours[s], label=s if i == 0 else None)
                    bottom += v
                rest = float(r["gpu_ms"]) - bottom
                if rest > 0:
                    ax.bar(x, rest, 0.9, bottom=bottom, color="#dddddd")
            else:
                ax.bar(x, float(r["gpu_ms"]), 0.9, color="#444444")
            bottom = 0.0
            for p in WALL_PARTS:
                v = float(r[p + "_ms"] or 0)
                ax.bar(x + 1, v, 0.9, bottom=bottom, color=wall_col[p], hatch="//",
                       label=WALL_LABELS[p] if i == 0 else None)
                bottom += v
            ax.text(x, float(r["gpu_ms"]), f"{float(r['gpu_ms']):.1f}", ha="center", va="bottom", fontsize=7)
            ax.text(x + 1, float(r["wall_ms"]), f"{float(r['wall_ms']):.0f}", ha="center", va="bottom", fontsize=7)
        ax.set_xticks([2.4 * i + 0.5 for i in range(len(rs))])
        ax.set_xticklabels([n.replace("gs-ibl cut", "ours, cut").replace("gs-ibl", "ours") for n in names],
                           fontsize=8)
        ax.set_title(f"{sc} ({int(rs[0]['splats']):,})", fontsize=9)
        ax.set_ylim(0, 1.12 * max(max(float(r["gpu_ms"]), float(r["wall_ms"])) for r in rs))
        ax.grid(True, axis="y", alpha=0.3)
    axes[0][0].set_ylabel("ms per frame (left bar GPU by stage, right bar wall)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 6), fontsize=7, frameon=False)
    r0 = rows[0]
    clocks = sorted(({r["sm_mhz_min"] for r in rows} | {r["sm_mhz_max"] for r in rows}) - {""})
    fig.suptitle(f"A final frame's splats, {r0['width']}x{r0['height']}: ours with a depth cut (FRONT/BEHIND) and "
                 f"without, gsplat 1.5.3 classic\n{r0['device']}"
                 + (f", SM {'/'.join(clocks)} MHz" if clocks else "") + f", {r0['date']}", fontsize=9)
    fig.tight_layout(rect=(0, 0.09, 1, 0.93))
    fig.savefig(args.png, dpi=110)
    print(f"wrote {args.png}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["bench", "plot"])
    ap.add_argument("--scenes", default="room,guitar,random:1M,random:3M,shell:1M,shell:3M")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--warmup", type=float, default=0.5, help="seconds of warm-up per renderer (after one frame)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--block", type=int, default=5)
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--gsplat-stages", action="store_true", help="gsplat's kernels by stage (torch profiler)")
    ap.add_argument("--deadline", type=float, default=0.0, help="seconds: scenes not begun by then are left out")
    ap.add_argument("--csv", default=os.path.join(ROOT, "out", "bench", "frame_cost.csv"))
    ap.add_argument("--png", default=os.path.join(ROOT, "docs", "final-frame-cost.png"))
    args = ap.parse_args(argv)
    {"bench": run_bench, "plot": run_plot}[args.mode](args)


if __name__ == "__main__":
    main()
