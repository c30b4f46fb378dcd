"""Our renderer against gsplat, same splats, same views (six cube faces, or a camera frame), one process, one GPU.

Adapted from shared/tools/gpu_peer/peer_bench.py (the same-process peer bench of 2026-12-01): gsplat's
``rasterization()`` (1.5.3, antialiased mode: its opacity compensation matches our energy-preserving probe
dilation) renders the six faces of ``ViewBatch.cubemap`` in one call; a camera frame (``--cameras 1920x1080``: one
pinhole view at the scene's centre, 60° across) is drawn by both in 3DGS's look (gsplat "classic"). Per scene x
splat count x view each renderer is warmed up, then timed in interleaved blocks; the SM clock (NVML) is read
before and after each block. A/B rows (``--ab``) draw with the first row's renderer, switches set otherwise; every
row of ours names the raster and emit kernels it ran (the kernel table's picks, render/kernel_table.py).

  python benchmarks/peer_bench.py bench [--scenes random,shell] [--counts 100000,1000000,6000000]
         [--faces 64,256,1024] [--cameras 1920x1080,3840x2160] [--ab plain,strips,emit-slot,emit-splat]
         [--gsplat-stages cameras] [--csv out/bench/peer.csv] [--camera-csv out/bench/camera.csv]
         [--profile-at 6000000@1024] [--deadline SECONDS]
  python benchmarks/peer_bench.py plot --csv docs/bench/peer_nvidia-h200.csv --png docs/performance.png
  python benchmarks/raster_ab_bench.py table out/bench/peer.csv ...   (the kernel table from the A/B rows)

Rows (one per renderer and configuration): GPU ms (ours: Vulkan timestamps; gsplat: CUDA events around the call),
wall ms (ours: render() on the host, the frame stays on the GPU; gsplat: the call and a synchronize), the pairs
each renders, and for ours the per-stage times beside each stage's memory-bandwidth floor: the bytes it must
move at the least (below) over the peak bandwidth NVML reports (memory clock x bus width x 2). Floors, bytes:
  preprocess  its reads (position, scale, rotation, SH: (48 + 12 K) per splat) + its writes per splat
              (the prepared splat, depth key and value, tile count, a tile rectangle per view)
  sort_depth  one read and one write of every (key, value) pair: 16 per splat (any sort moves at least that)
  emit        the tile counts in depth order and their prefix sum (16 per splat) + 8 per pair written
  sort_tiles  16 per pair (one read and one write)
  ranges      4 per pair drawn + 8 per tile
  raster      4 per pair drawn + the prepared splats once + 16 per pixel written
--profile-at N@FACE,... adds a run of our renderer with a timestamp after every sort step (hist, scan, scatter)
and gsplat's kernel times (torch profiler) there. On the GPU machine: a CUDA context (torch, needed for gsplat
anyway) holds the SM clock (docs/benchmarks.md); gsplat JIT-compiles its CUDA on first use (~50 s for sm_90
with TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=16); GSPLAT_SO=path/gsplat_cuda.so loads a build kept from before.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from bench_common import append_csv, bench_scene, kernels_from, shell_scene, trial_dirs  # noqa: E402

STAGES = ("preprocess", "sort_depth", "emit", "sort_tiles", "ranges", "raster")
DEFAULTS: dict = {}  # default_switches(), taken before any row sets them
SCENES = {"random": lambda n: bench_scene(n, 3, 5.0), "shell": shell_scene}
T0 = time.perf_counter()


def log(*a) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s]", *a, flush=True)


class Nvml:
    """SM clock and peak memory bandwidth of GPU 0; empty where NVML is missing."""

    def __init__(self) -> None:
        self.h = None
        try:
            import pynvml
            pynvml.nvmlInit()
            self.nv, self.h = pynvml, pynvml.nvmlDeviceGetHandleByIndex(0)
        except Exception:  # noqa: BLE001 - no NVML: no clock column
            pass

    def sm_mhz(self) -> int | str:
        try:
            return int(self.nv.nvmlDeviceGetClockInfo(self.h, self.nv.NVML_CLOCK_SM))
        except Exception:  # noqa: BLE001
            return ""

    def info(self) -> dict:
        out = {}
        try:
            nv, h = self.nv, self.h
            out["gpu"] = nv.nvmlDeviceGetName(h)
            out["driver"] = nv.nvmlSystemGetDriverVersion()
            mem = nv.nvmlDeviceGetMaxClockInfo(h, nv.NVML_CLOCK_MEM)
            bus = nv.nvmlDeviceGetMemoryBusWidth(h)
            out["peak_gbs"] = round(mem * 1e6 * 2 * bus / 8 / 1e9, 1)
        except Exception:  # noqa: BLE001
            pass
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in out.items()}


def stage_floor_bytes(n: int, sh_k: int, pairs: int, drawn: int, tiles: int, pixels: int, views: int) -> dict:
    """The least bytes each stage must move (module docstring)."""
    from gs_ibl_addon.core.vk.constants import PREP
    return {"preprocess": n * (48 + 12 * sh_k) + n * (PREP * 16 + 12 + 8 * views),
            "sort_depth": 16 * n, "emit": 16 * n + 8 * pairs, "sort_tiles": 16 * pairs,
            "ranges": 4 * drawn + 8 * tiles, "raster": 4 * drawn + PREP * 16 * n + 16 * pixels}


# A/B rows (--ab): our renderer with some of the raster's module switches set otherwise (renderer.py says what each
# does), measured in the same blocks as the rest. Without a switch set, the kernel table (render/kernel_table.json)
# picks the raster and emit kernels; each row records which it ran (raster_kernel, emit_kernel).
VARIANTS = {
    "ray": ("gs-ibl ray test only", dict(PLANE_FORMS=False)),  # no plane forms
    "plain": ("gs-ibl without strips", dict(RASTER_STRIPS=False)),
    "strips": ("gs-ibl strips", dict(RASTER_STRIPS=True)),
    "strips-noconic": ("gs-ibl strips, no conic", dict(RASTER_STRIPS=True, CONIC_MAX_FACE=0)),
    "emit-slot": ("gs-ibl emit per slot", dict(EMIT_PER_SPLAT=False)),
    "emit-splat": ("gs-ibl emit per splat", dict(EMIT_PER_SPLAT=True)),
    "sh-splat": ("gs-ibl SH splat-major", dict(SH_SPLAT_MAJOR=True)),
    "sh-coef": ("gs-ibl SH coefficient-major", dict(SH_SPLAT_MAJOR=False)),
    "no-compact": ("gs-ibl every splat depth-sorted", dict(COMPACT_VIEWS=False)),
}
# Switches read when a renderer uploads its scene, not when it records: a row that sets one has a renderer of its own.
UPLOAD_SWITCHES = {"SH_SPLAT_MAJOR"}
# The variants that time one choice of the kernel table against the other (kernel_table.CHOICES): variant ->
# (stage, kernel). raster_ab_bench.py table makes the table from rows of these.
TABLE_VARIANTS = {"plain": ("raster", "plain"), "strips": ("raster", "strips"),
                  "emit-slot": ("emit", "slot"), "emit-splat": ("emit", "splat")}
CAMERA_FOV = 60.0  # degrees, horizontal; the camera sits at the scene's centre looking along +X (parse_views)


def parse_views(faces: str, cameras: str = "") -> list[tuple[str, int, int]]:
    """("cube", face, face) for each of ``faces`` and ("camera", width, height) for each WxH of ``cameras``."""
    out = [("cube", int(f), int(f)) for f in faces.split(",") if f]
    for c in cameras.split(","):
        if c:
            w, h = (int(x) for x in c.lower().split("x"))
            out.append(("camera", w, h))
    return out


def view_batch(view: tuple[str, int, int]):
    """Our ViewBatch for a parse_views entry: the probe cube at the origin, or a pinhole camera there (3DGS's
    look: dilated by its pixel)."""
    from gs_ibl_addon.core.render.views import ViewBatch
    kind, w, h = view
    if kind == "cube":
        return ViewBatch.cubemap([0.0, 0.0, 0.0], w)
    return ViewBatch.pinhole([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], CAMERA_FOV, w, h)


def view_label(view: tuple[str, int, int]) -> str:
    kind, w, h = view
    return f"{w}²" if kind == "cube" else f"{w}x{h}"


def default_switches() -> dict:
    """Every switch a variant sets, at the renderer's own values (each row sets all of them before it renders)."""
    from gs_ibl_addon.core.render import renderer
    return {k: getattr(renderer, k) for _, sw in VARIANTS.values() for k in sw}


class Ours:
    """Our renderer; ``variant``: a VARIANTS key, an A/B row with one of the raster's switches off; ``trial``: a
    folder of trial kernels (benchmarks/kernel_trials.py build), an A/B row on a Vulkan context of its own whose
    pipelines take those kernels. ``share``: a variant draws with that row's renderer (its scene uploaded once: a
    switch is part of the key of the programs a renderer records, so each variant records and keeps its own)."""

    def __init__(self, scene, ctx, variant: str | None = None, trial: str | None = None,
                 share: "Ours | None" = None) -> None:
        from gs_ibl_addon.core.render import renderer
        from gs_ibl_addon.core.vk.context import VulkanContext
        self.trial, self.variant = trial, variant or ""
        self.own_ctx = VulkanContext() if trial else None
        self.name, off = VARIANTS[variant] if variant else ("gs-ibl", {})
        self.owner = share is None or trial is not None or bool(UPLOAD_SWITCHES & set(off))
        if self.owner:
            before = {k: getattr(renderer, k) for k in UPLOAD_SWITCHES}
            try:
                for k in UPLOAD_SWITCHES & set(off):
                    setattr(renderer, k, off[k])
                with kernels_from(trial):
                    self.r = renderer.SplatRenderer(scene, self.own_ctx or ctx)
            finally:
                for k, v in before.items():
                    setattr(renderer, k, v)
        else:
            self.r = share.r
        self.sh_k = scene.sh.shape[1]
        if trial:
            self.name = f"gs-ibl [{os.path.basename(os.path.normpath(trial))}]"
        if not DEFAULTS:  # the first row is made before any row has set a switch
            DEFAULTS.update(default_switches())
        self.switches = {**DEFAULTS, **off}

    def _switch(self) -> None:
        from gs_ibl_addon.core.render import renderer
        for k, v in self.switches.items():  # read when a batch shape's program is first recorded
            setattr(renderer, k, v)

    def set_face(self, face: int) -> None:
        self.set_view(("cube", face, face))

    def set_view(self, view: tuple[str, int, int]) -> None:
        from gs_ibl_addon.core.render.renderer import _views_buffer_data
        self.batch = view_batch(view)
        _, self.tiles, self.pixels = _views_buffer_data(self.batch)

    def kernels(self) -> dict:
        """The raster and emit kernels this row's switches take for the current batch (renderer.batch_kernels)."""
        from gs_ibl_addon.core.render import renderer
        self._switch()
        return renderer.batch_kernels(self.r.ctx, self.batch, self.tiles)

    def rep(self) -> dict:
        self._switch()
        with kernels_from(self.trial):  # a batch shape's first frame makes its pipelines
            t0 = time.perf_counter()
            res = self.r.render(self.batch, timestamps=True)
            wall = (time.perf_counter() - t0) * 1e3
        t = res.timings_ms
        out = {"gpu_ms": t["total"], "wall_ms": wall, "pairs": res.instances}
        for s in STAGES:
            out[s] = t.get(s, 0.0) + sum(v for k, v in t.items() if k.startswith(s + "."))
        return out

    def drawn_pairs(self) -> int:
        """Pairs the raster drew in the last render (the tile sort leaves out those whose tile was missed)."""
        return int(self.r.count.read(np.uint32, 1)[0])

    def images(self) -> np.ndarray:
        self._switch()
        with kernels_from(self.trial):
            return np.stack(self.r.render(self.batch).images)

    def close(self) -> None:
        if self.owner:
            self.r.close()
        if self.own_ctx is not None:
            self.own_ctx.close()


def load_gsplat():
    """gsplat with its CUDA backend; GSPLAT_SO (a gsplat_cuda.so built before) skips the JIT compile."""
    import importlib.util
    import torch  # noqa: F401
    so = os.environ.get("GSPLAT_SO")
    if so and os.path.exists(so):
        spec = importlib.util.spec_from_file_location("gsplat_cuda", so)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        sys.modules["gsplat.csrc"] = mod
    import gsplat
    from gsplat.cuda._backend import _C
    if _C is None:
        raise RuntimeError("gsplat's CUDA backend did not load")
    return gsplat


class Gsplat:
    name = "gsplat"

    def __init__(self, scene) -> None:
        import gsplat
        import torch
        self.torch, self.raster = torch, gsplat.rasterization
        f = lambda a: torch.from_numpy(np.ascontiguousarray(a, np.float32)).cuda()  # noqa: E731
        self.t = (f(scene.positions), f(scene.rotations), f(scene.scales), f(scene.opacities), f(scene.sh))
        self.e0, self.e1 = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)

    def set_face(self, face: int) -> None:
        self.set_view(("cube", face, face))

    def set_view(self, view: tuple[str, int, int]) -> None:
        """gsplat's OpenCV cameras (x right, y down, z forward: a proper rotation) from our views. Our cube faces
        are left-handed: their cameras take x = -right, so gsplat's images are ours mirrored left-right and
        images() flips them back. A cube is a probe, drawn with its opacity compensation ("antialiased", as our
        energy-preserving probe dilation); a camera is 3DGS's look ("classic", as our pinhole batches)."""
        batch = view_batch(view)
        vms, ks, self.mirror = [], [], False
        for v in batch.views:
            right = np.asarray(v.right)
            if np.dot(np.cross(right, v.down), v.forward) < 0:
                right, self.mirror = -right, True
            rot = np.stack([right, np.asarray(v.down), np.asarray(v.forward)])
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = rot, -rot @ batch.origin
            vms.append(m)
            ks.append([[v.width / (2 * v.tan_x), 0, v.width / 2], [0, v.height / (2 * v.tan_y), v.height / 2],
                       [0, 0, 1]])
        tt = lambda a: self.torch.tensor(np.array(a), dtype=self.torch.float32, device="cuda")  # noqa: E731
        self.size, self.vm, self.k = (view[1], view[2]), tt(vms), tt(ks)
        self.mode = "antialiased" if view[0] == "cube" else "classic"

    def call(self):
        return self.raster(*self.t, self.vm, self.k, *self.size, sh_degree=3, near_plane=0.01,
                           rasterize_mode=self.mode, packed=True)

    readback = False  # a final frame's peer reads its images back to the host, as ours does there

    def rep(self) -> dict:
        """One call: GPU ms between CUDA events, wall ms to the synchronize (and the readback, where asked)."""
        torch = self.torch
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        self.e0.record()
        colors, alphas, meta = self.call()
        self.e1.record()
        torch.cuda.synchronize()
        if self.readback:
            colors.cpu().numpy(), alphas.cpu().numpy()
        wall = (time.perf_counter() - t0) * 1e3
        return {"gpu_ms": self.e0.elapsed_time(self.e1), "wall_ms": wall, "pairs": int(meta["isect_ids"].numel())}

    def images(self) -> np.ndarray:
        colors, alphas, _ = self.call()
        im = np.concatenate([colors.float().cpu().numpy(), alphas.float().cpu().numpy()], -1)
        return np.ascontiguousarray(im[:, :, ::-1] if self.mirror else im)

    def kernel_ms(self) -> list[tuple[str, float]]:
        """Per-kernel GPU ms per call (torch profiler over 5 calls), largest first."""
        from torch.profiler import ProfilerActivity, profile
        self.torch.cuda.synchronize()
        with profile(activities=[ProfilerActivity.CUDA]) as prof:
            for _ in range(5):
                self.call()
            self.torch.cuda.synchronize()
        rows = []
        for e in prof.key_averages():
            dt = getattr(e, "device_time_total", None) or getattr(e, "cuda_time_total", 0.0)
            if dt and dt > 0 and not e.key.startswith("ProfilerStep"):
                rows.append((e.key[:80], dt / 5 / 1000.0))
        return sorted(rows, key=lambda r: -r[1])


def timed(rends: list, nv: Nvml, warmup_s: float, rounds: int, block: int) -> dict:
    """Warm each renderer up, then interleave blocks of reps; per renderer its reps and block clocks."""
    for r in rends:
        t = time.perf_counter()
        while time.perf_counter() - t < warmup_s:
            r.rep()
    reps = {r.name: [] for r in rends}
    clocks = {r.name: [] for r in rends}
    for _ in range(rounds):
        for r in rends:
            c0 = nv.sm_mhz()
            reps[r.name] += [r.rep() for _ in range(block)]
            clocks[r.name] += [c0, nv.sm_mhz()]
    return {r.name: (reps[r.name], [c for c in clocks[r.name] if c != ""]) for r in rends}


GSPLAT_STAGES = (("projection", "preprocess"), ("spherical_harmonics", "preprocess"), ("sh_", "preprocess"),
                 ("isect_tiles", "emit"), ("intersect_tile", "emit"), ("radix", "sort_tiles"), ("sort", "sort_tiles"),
                 ("isect_offset", "ranges"), ("intersect_offset", "ranges"), ("rasterize", "raster"))


def gsplat_stages(kernels: list[tuple[str, float]]) -> dict[str, float]:
    """gsplat's kernel times (Gsplat.kernel_ms) summed into our stages' names: projection and SH -> preprocess,
    tile intersections -> emit, its one radix sort of (camera, tile, depth) keys -> sort_tiles (it has no sort by
    depth of its own), tile offsets -> ranges, rasterize -> raster, the rest (torch's own kernels) -> other."""
    out = dict.fromkeys(STAGES + ("other",), 0.0)
    for name, ms in kernels:
        low = name.lower()
        out[next((st for key, st in GSPLAT_STAGES if key in low), "other")] += ms
    return out


def run_bench(args) -> None:
    import gs_ibl_addon.core.render.renderer as renderer_module
    from gs_ibl_addon.core.render import kernel_table
    from gs_ibl_addon.core.vk import get_context
    nv = Nvml()
    info = nv.info()
    import torch
    torch.zeros(1, device="cuda")  # the CUDA context that holds the SM clock (gsplat needs it anyway)
    t = time.perf_counter()
    gsplat = load_gsplat()
    log(f"gsplat {gsplat.__version__} ready in {time.perf_counter() - t:.1f} s")
    ctx = get_context()
    date = datetime.date.today().isoformat()
    peak = info.get("peak_gbs", 0.0) * 1e9
    dev_class = kernel_table.context_class(ctx)
    log(f"device {ctx.device_name} (kernel table class {dev_class}), NVML {info}")
    profile_at = {tuple(int(x) for x in p.split("@")) for p in args.profile_at.split(",") if p}
    views = parse_views(args.faces, args.cameras)
    deadline = T0 + args.deadline if args.deadline else None
    for kind in args.scenes.split(","):
        for n in [int(x) for x in args.counts.split(",")]:
            if deadline and time.perf_counter() > deadline:
                log(f"past --deadline {args.deadline:.0f} s: {kind} {n:,} left out")
                continue
            t = time.perf_counter()
            scene = SCENES[kind](n)
            ours, peer = Ours(scene, ctx), Gsplat(scene)
            variants = [Ours(scene, ctx, v, share=ours) for v in args.ab.split(",") if v]
            variants += [Ours(scene, ctx, trial=t) for t in trial_dirs(args.trials)]
            log(f"{kind} {n:,}: scene and uploads {time.perf_counter() - t:.1f} s")
            for view in views:
                if deadline and time.perf_counter() > deadline:
                    log(f"past --deadline {args.deadline:.0f} s: {kind} {n:,} {view_label(view)} left out")
                    continue
                vkind, width, height = view
                face = max(width, height)
                for r in (ours, *variants, peer):
                    r.set_view(view)
                got = timed([ours, *variants, peer], nv, args.warmup, args.rounds, args.block)
                ref, im = ours.images(), peer.images()
                diff = float(np.abs(ref[..., :3] - im[..., :3]).mean() / max(float(ref[..., :3].mean()), 1e-12))
                drawn = ours.drawn_pairs()
                peer_stages = None
                if args.gsplat_stages == "all" or (args.gsplat_stages == "cameras" and vkind == "camera"):
                    peer_kernels = peer.kernel_ms()
                    peer_stages = gsplat_stages(peer_kernels)
                    log("  gsplat kernels (ms per call): " + ", ".join(f"{k} {v:.3f}" for k, v in peer_kernels[:10]))
                rows = []
                for r in (ours, *variants, peer):
                    reps, clk = got[r.name]
                    gpu = [x["gpu_ms"] for x in reps]
                    kern = r.kernels() if r is not peer else {}
                    row = {"device": ctx.device_name, "device_class": dev_class, "driver": info.get("driver", ""),
                           "date": date, "scene": kind, "splats": n, "view": vkind, "width": width, "height": height,
                           "face": face, "renderer": r.name, "variant": getattr(r, "variant", ""),
                           "raster_kernel": kern.get("raster", ""), "emit_kernel": kern.get("emit", ""),
                           "gpu_ms": round(statistics.median(gpu), 4),
                           "gpu_min_ms": round(min(gpu), 4), "gpu_max_ms": round(max(gpu), 4),
                           "wall_ms": round(statistics.median(x["wall_ms"] for x in reps), 3),
                           "pairs": reps[-1]["pairs"], "pairs_drawn": drawn if r is not peer else "",
                           "sm_mhz_min": min(clk) if clk else "", "sm_mhz_max": max(clk) if clk else "",
                           "image_diff": round(diff, 4) if r is peer else "",
                           "coverage": round(float((im if r is peer else ref)[..., 3].mean()), 4)}
                    if r is not peer:
                        floors = stage_floor_bytes(n, ours.sh_k, row["pairs"], drawn, ours.tiles, ours.pixels,
                                                   len(ours.batch.views))
                        for s in STAGES:
                            row[f"{s}_ms"] = round(statistics.median(x[s] for x in reps), 4)
                            row[f"{s}_floor_ms"] = round(floors[s] / peak * 1e3, 4) if peak else ""
                        row["other_ms"] = ""
                    else:  # gsplat's kernels by stage, where asked (--gsplat-stages); no floors
                        for s in STAGES:
                            row[f"{s}_ms"] = round(peer_stages[s], 4) if peer_stages else ""
                            row[f"{s}_floor_ms"] = ""
                        row["other_ms"] = round(peer_stages["other"], 4) if peer_stages else ""
                    rows.append(row)
                for v in variants:  # how far the variant's image is from ours: same image_diff measure
                    vim = v.images()  # (the kernels' A/B rows draw it bit for bit: a cheap test first)
                    rows[1 + variants.index(v)]["image_diff"] = 0.0 if np.array_equal(ref, vim) else round(float(
                        np.abs(ref[..., :3] - vim[..., :3]).mean() / max(float(ref[..., :3].mean()), 1e-12)), 7)
                append_csv(args.camera_csv if vkind == "camera" and args.camera_csv else args.csv, rows)
                o, g = rows[0], rows[-1]
                for v in rows[1:-1]:
                    log(f"  {v['renderer']}: {v['gpu_ms']:.3f} (raster {v['raster_ms']:.2f}; diff {v['image_diff']})")
                log(f"{kind} {n:>9,} {view_label(view):>9}: ours {o['gpu_ms']:.3f} (wall {o['wall_ms']:.2f}; "
                    f"{o['raster_kernel']}, {o['emit_kernel']}) gsplat {g['gpu_ms']:.3f} (wall {g['wall_ms']:.2f}) "
                    f"ratio {o['gpu_ms'] / g['gpu_ms']:.2f} | pairs {o['pairs']:,}/{drawn:,} vs {g['pairs']:,} | SM "
                    f"{o['sm_mhz_min']}-{o['sm_mhz_max']} | "
                    + " ".join(f"{s} {o[s + '_ms']:.2f}/{o[s + '_floor_ms']}" for s in STAGES) + f" | diff {diff:.3f}"
                    + (" | gsplat " + " ".join(f"{s} {g[s + '_ms']:.2f}" for s in STAGES + ("other",))
                       if peer_stages else ""))
                if (n, face) in profile_at and vkind == "cube":
                    renderer_module.PROFILE_SORTS = True
                    prof = Ours(scene, ctx)
                    prof.set_view(view)
                    for _ in range(5):
                        prof.rep()
                    tms = [prof.r.render(prof.batch, timestamps=True).timings_ms for _ in range(10)]
                    keys = [k for k in tms[0] if "." in k]
                    log("  our sort steps (ms, summed over passes): "
                        + ", ".join(f"{k} {statistics.median(x[k] for x in tms):.3f}" for k in keys))
                    prof.close()
                    renderer_module.PROFILE_SORTS = False
                    log("  gsplat kernels (ms per call): "
                        + ", ".join(f"{k} {v:.3f}" for k, v in peer.kernel_ms()[:12]))
            for v in variants:
                v.close()
            ours.close()
            del peer, scene
            torch.cuda.empty_cache()


def run_plot(args) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with open(args.csv) as f:
        rows = [r for r in csv.DictReader(f) if r.get("view", "cube") in ("cube", "")]  # cube faces only
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    faces = sorted({int(r["face"]) for r in rows})
    fig, axes = plt.subplots(len(scenes), len(faces), figsize=(4.2 * len(faces), 3.6 * len(scenes)), squeeze=False,
                             sharey=True)
    style = {("gs-ibl", "gpu_ms"): ("C0", "-", "ours GPU"), ("gs-ibl", "wall_ms"): ("C0", ":", "ours wall"),
             ("gsplat", "gpu_ms"): ("C3", "-", "gsplat GPU"), ("gsplat", "wall_ms"): ("C3", ":", "gsplat wall"),
             ("gs-ibl strips", "gpu_ms"): ("C2", "--", "ours GPU, strip kernels (A/B)"),  # drawn where measured
             ("gs-ibl without strips", "gpu_ms"): ("C1", "--", "ours GPU, plain raster (A/B)")}
    for i, sc in enumerate(scenes):
        for j, face in enumerate(faces):
            ax = axes[i][j]
            for (rend, col), (c, ls, label) in style.items():
                pts = sorted((int(r["splats"]), float(r[col])) for r in rows
                             if r["scene"] == sc and int(r["face"]) == face and r["renderer"] == rend)
                if pts:
                    ax.plot(*zip(*pts), color=c, linestyle=ls, marker="o", ms=3, label=label)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(f"{sc}, six {face}² faces", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            if i == len(scenes) - 1:
                ax.set_xlabel("splats")
            if j == 0:
                ax.set_ylabel("ms")
    axes[0][0].legend(fontsize=8)
    r0 = rows[0]
    clocks = sorted({r["sm_mhz_min"] for r in rows} | {r["sm_mhz_max"] for r in rows})
    fig.suptitle(f"gs-ibl vs gsplat 1.5.3 (antialiased), one process: {r0['device']}, driver {r0['driver']}, "
                 f"SM {'/'.join(c for c in clocks if c)} MHz, {r0['date']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)
    print(f"wrote {args.png}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["bench", "plot"])
    ap.add_argument("--scenes", default="random,shell")
    ap.add_argument("--counts", default="100000,1000000,6000000")
    ap.add_argument("--faces", default="64,256,1024", help="cube faces (six views at the origin); empty: none")
    ap.add_argument("--cameras", default="", help="WxH,...: camera frames (one pinhole view at the origin along +X, "
                    f"{CAMERA_FOV:.0f}° across), timed like the faces")
    ap.add_argument("--camera-csv", help="where the camera frames' rows go (default: --csv)")
    ap.add_argument("--gsplat-stages", choices=("", "cameras", "all"), default="",
                    help="gsplat's kernels by stage (torch profiler, 5 calls) in its rows: for camera frames, or all")
    ap.add_argument("--deadline", type=float, default=0.0, help="seconds: configurations not begun by then are "
                    "left out (logged), so a run ends inside its machine's limit with what it measured")
    ap.add_argument("--warmup", type=float, default=1.0, help="seconds of warm-up per renderer and configuration")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--block", type=int, default=10)
    ap.add_argument("--coalesce", type=int, choices=(0, 1), help="radix8_scatter's way of writing (gpu_sort.COALESCE)")
    ap.add_argument("--conic-faces", help="MIN:MAX, the face sizes that raster with the conic pre-test "
                    "(renderer.CONIC_MIN_FACE, CONIC_MAX_FACE)")
    ap.add_argument("--ab", default="", help="comma-separated VARIANTS (ray: no plane forms): our renderer "
                    "with that switch off, rows of their own in the same blocks")
    ap.add_argument("--trials", help="a folder of trial builds of our kernels (one subfolder of NAME.spv files a "
                    "trial: benchmarks/kernel_trials.py build): A/B rows, each on a Vulkan context of its own")
    ap.add_argument("--profile-at", default="", help="N@FACE,...: sort steps and gsplat's kernels there")
    ap.add_argument("--csv", default=os.path.join(HERE, "..", "out", "bench", "peer.csv"))
    ap.add_argument("--png", default=os.path.join(HERE, "..", "docs", "performance.png"))
    args = ap.parse_args()
    if args.coalesce is not None:
        from gs_ibl_addon.core.render import gpu_sort
        gpu_sort.COALESCE = args.coalesce
    if args.conic_faces:
        from gs_ibl_addon.core.render import renderer
        renderer.CONIC_MIN_FACE, renderer.CONIC_MAX_FACE = (int(x) for x in args.conic_faces.split(":"))
    {"bench": run_bench, "plot": run_plot}[args.mode](args)


if __name__ == "__main__":
    main()
