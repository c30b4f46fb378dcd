"""The bake of benchmarks/native_bench.py's scene without Blender: what the GPU machine's series on that chart
costs (issue 22, goal 3).

Run: python benchmarks/auto_bake_core.py [--repeats 3] [--lighting auto,volume] [--out CSV] [--volume-out CSV]
     python benchmarks/auto_bake_core.py --stages [--ab] [--gpu-paths] [--repeats 5] [--out CSV]

The sample room, the probe at the white sphere ((0, 0.45, 1.0), radius 0.3: blender_scene.ROOM_SPHERE), the panel's
defaults and Lighting Auto's work as blender/lighting/bake.py bake_into_world and blender/lighting/auto_light.py do
it, on one uploaded renderer (Blender's splat cache keeps it between bakes): the World probe's bake and its files
(core CLI: write_probe), the 9-point measurement in one batch with the World probe's place, and the nodes of the
sphere's grid the measurement did not place (18 of 3 x 3 x 3, 116 of 5 x 5 x 5), when it asks for a grid. Wall
time: median of --repeats after one warm-up; the device, driver, date and SM clock (held by a CUDA context:
bench_common) on the row. Appends to --out (default docs/bench/auto_bake_core_<device>.csv). Lighting Volume's
bake of the same sphere (volume_bake: the World probe, its files and the volume over the sphere's box, as
blender/lighting/volume.py) goes to --volume-out (default docs/bench/volume_bake_core_<device>.csv): native_bench.py
draws both as the GPU machine's series.

``--stages [--ab]`` (issue 38: a bake whose wall time is its GPU time): per stage, wall time beside the GPU time of the
submissions it waited for (every recording timestamped: the context's stamp_all) and the submissions it made, host
= wall - GPU, for three pieces of work on the one uploaded renderer: the sample's default bake (the command line's:
face size and irradiance size from the tolerance, the probe at the splats' centre; its stages as bake_probe reports
them, core/stage_times.py), Lighting Auto's bake of the sphere (the World probe, the measurement, the grid nodes;
each a stage) and a 1920x1080 camera frame from the World probe's place (render_camera, depth on, no cut). Medians
of --repeats after one warm-up. With --ab every run is also made with the host work the issue moved put back
(host_paths: holes filled in numpy, numpy per-face parts, the enclosure masks made anew, the per-face cube put
together on the host), the two alternating, so
"before" and "after" share the machine's load. Prints a table; appends to --out (default
docs/bench/bake_stages_<device>.csv). ``--gpu-paths`` (a CPU device): where a bake picks its path by device, the
one a GPU takes (the per-face search's parts as a filter, bake.parts_on_gpu, not numpy), so lavapipe's host time
is a GPU's code's (rows marked config "... gpu-paths").
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import os
import statistics
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests", "real_blender"))
from bench_common import append_csv, gpu_clock, hold_gpu_clock  # noqa: E402
from blender_scene import ROOM_SPHERE  # noqa: E402 (native_bench.py's sphere)
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe, default_probe_position  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe.auto_light import (AutoLight, auto_light_batches, measure_bake,  # noqa: E402
                                                run_batches)
from gs_ibl_addon.core.probe import volume as pv  # noqa: E402
from gs_ibl_addon.core.probe.volume_refine import bake_light_volume  # noqa: E402
from gs_ibl_addon.core.probe.result import write_probe  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402
from gs_ibl_addon.core.stage_times import StageTimes, stages  # noqa: E402
from gs_ibl_addon.core.vk import get_context  # noqa: E402

REPO = os.path.dirname(HERE)
PROBE = np.array(ROOM_SPHERE["centre"])
RADIUS = ROOM_SPHERE["radius"]
TOLERANCE = 0.05  # the panel's Variation Tolerance


def sphere_auto(r: SplatRenderer, stage=None) -> AutoLight:
    """Lighting Auto for the sphere (core/probe/auto_light.py, as blender/lighting/auto_light.py bakes it), each
    batch inside ``stage(name)`` when given: "measurement", then "grid" when the sphere gets one."""
    names, bake = iter(("measurement", "grid")), measure_bake(r)

    def staged(points):
        with stage(next(names)) if stage else contextlib.nullcontext():
            return bake(points)
    return run_batches(auto_light_batches(PROBE, [(PROBE - RADIUS, PROBE + RADIUS)], ["sphere"], TOLERANCE), staged)


def sphere_volume(r: SplatRenderer):
    """Lighting Volume's volume over the sphere's box (core bake_light_volume, the default budget and face)."""
    return bake_light_volume(r, [(PROBE - RADIUS, PROBE + RADIUS)])[1]


def auto_bake(r: SplatRenderer, scene, out_dir: str) -> dict:
    """One bake as the panel's Bake does it: (wall seconds per stage, the light the sphere got)."""
    t = {"start": time.perf_counter()}
    result = bake_probe(None, PROBE, ProbeSettings(), renderer=r, host_splats=scene)
    t["world probe"] = time.perf_counter()
    write_probe(result, out_dir)
    t["writing"] = time.perf_counter()

    @contextlib.contextmanager
    def mark(name):
        yield
        t[name] = time.perf_counter()
    light = sphere_auto(r, mark)
    t["measurement"] = t.get("measurement", t["writing"])  # the choice's host work goes with the grid's batch
    t["grid"] = time.perf_counter()
    names = list(t)
    stages = {b: t[b] - t[a] for a, b in zip(names, names[1:])}
    return {"wall_s": t["grid"] - t["start"], **stages, "choice": light.choices[0].kind,
            "faces": "/".join(str(x) for x in result.settings.get("face_sizes", []))}


def volume_bake(r: SplatRenderer, scene, out_dir: str) -> dict:
    """One Lighting Volume bake as the panel's Bake does it (blender/lighting/volume.py _bake): the World probe and
    its files, the volume over the sphere's box, the World probe's SH at its place, the images packed. Wall
    seconds per stage, and the probes."""
    t = {"start": time.perf_counter()}
    result = bake_probe(None, PROBE, ProbeSettings(), renderer=r, host_splats=scene)
    t["world probe"] = time.perf_counter()
    write_probe(result, out_dir)
    t["writing"] = time.perf_counter()
    vol = sphere_volume(r)
    measure_bake(r)(PROBE[None])  # the EEVEE output's World light
    pv.pack_atlas(vol), pv.pack_cells(vol)
    t["volume"] = time.perf_counter()
    names = list(t)
    return {"wall_s": t["volume"] - t["start"], **{b: t[b] - t[a] for a, b in zip(names, names[1:])},
            "probes": int(vol.timings.get("probes", vol.spec.count))}


def stage_runs(r: SplatRenderer, scene) -> dict[str, dict[str, dict[str, float]]]:
    """{work: {stage: {wall, gpu, host, submits}}} of one run of each piece of work (--stages)."""
    out = {}
    ctx = r.ctx
    before, t0 = ctx.stats.snapshot(), time.perf_counter()
    result = bake_probe(None, default_probe_position(scene), ProbeSettings(), renderer=r, host_splats=scene)
    moved = ctx.stats.since(before)
    out["default bake"] = {**stages(result.timings_ms), "all": {
        "wall": (time.perf_counter() - t0) * 1e3, "gpu": moved["gpu_ms"], "submits": moved["submits"]}}
    timings: dict[str, float] = {}
    times = StageTimes(ctx, timings)
    with times.stage("all"):
        with times.stage("world probe"):
            bake_probe(None, PROBE, ProbeSettings(), renderer=r, host_splats=scene)
        sphere_auto(r, times.stage)
    rows = stages(timings)
    out["auto bake"] = {k: rows[k] for k in ("world probe", "measurement", "grid", "all") if k in rows}
    cam = np.eye(4)
    cam[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # looking along +Y, Z up (Blender's front view turned round)
    cam[:3, 3] = PROBE
    timings = {}
    with StageTimes(ctx, timings).stage("all"):
        r.render_camera(ViewBatch.camera(cam, np.tan(np.radians(30)), np.tan(np.radians(30)) * 1080 / 1920,
                                         1920, 1080))
    out["camera 1080p"] = stages(timings)
    return out


@contextlib.contextmanager
def host_paths():
    """--ab's "before": the host work issue 38 moved, put back for a peer in the same run: holes filled in numpy
    and uploaded again, the search's per-face parts in numpy on every device, the enclosure check's half-sphere
    masks made on every bake, a per-face cube put together on the host (faces read back, resized, uploaded)."""
    from gs_ibl_addon.core import bake, bake_batch
    from gs_ibl_addon.core.probe import near
    from gs_ibl_addon.core.probe.reference import exact_irradiance_parts
    saved = (bake.GPU_FILLS, bake_batch.GPU_FILLS, bake.irradiance_parts, near._halves, bake.GPU_ASSEMBLE)
    bake.GPU_FILLS = bake_batch.GPU_FILLS = ()
    bake.irradiance_parts = lambda change, size, ctx=None: exact_irradiance_parts(change, size)
    near._halves = near._halves.__wrapped__
    bake.GPU_ASSEMBLE = False
    try:
        yield
    finally:
        bake.GPU_FILLS, bake_batch.GPU_FILLS, bake.irradiance_parts, near._halves, bake.GPU_ASSEMBLE = saved


def main_stages(a, info: dict) -> None:
    """--stages: a new process's first costs (the context, reading and upload, the first bake with its pipelines;
    pipeline_cache_bytes: what the disk cache gave the driver), then medians of the warm runs; with --ab each warm
    run also with the host paths the issue replaced (host_paths), the two alternating."""
    t0 = time.perf_counter()
    ctx = get_context()
    ctx.stamp_all = True  # every submission's GPU time is counted (TransferStats.gpu_ms)
    t1 = time.perf_counter()
    scene = read_scene(os.path.join(REPO, "samples", "room.ply"))
    r = SplatRenderer(scene, ctx)
    t2 = time.perf_counter()
    info["device"] = ctx.device_name
    first = stage_runs(r, scene)  # also the warm-up: pipelines, programs, first allocations
    process = {"context": {"wall": (t1 - t0) * 1e3, "gpu": 0.0, "submits": 0},
               "read and upload": {"wall": (t2 - t1) * 1e3, "gpu": 0.0, "submits": 0},
               "first default bake": first["default bake"]["all"], "first auto bake": first["auto bake"]["all"]}
    if a.gpu_paths:
        from gs_ibl_addon.core import bake
        bake.parts_on_gpu = lambda ctx: True
    configs = {"after": [], "before": []} if a.ab else {"": []}
    if a.gpu_paths:
        configs = {f"{k} gpu-paths".strip(): v for k, v in configs.items()}
    for _ in range(a.repeats):
        for config, runs in configs.items():
            with host_paths() if config.startswith("before") else contextlib.nullcontext():
                runs.append(stage_runs(r, scene))
    r.close()
    rows = []
    print(f"{'config':<16} {'work':<14} {'stage':<20} {'wall ms':>9} {'GPU ms':>9} {'host ms':>9} {'submits':>8}")
    for config, runs in configs.items():
        for run in runs:
            run["new process"] = process
        for work, table in {"new process": process, **runs[0]}.items():
            for stage in table:
                med = {f: statistics.median(run[work][stage][f] for run in runs) for f in ("wall", "gpu", "submits")}
                row = {"date": datetime.date.today().isoformat(), "device": info["device"],
                       "driver": info["driver"], "sm_mhz": gpu_clock(), "load": round(os.getloadavg()[0], 2),
                       "repeats": a.repeats, "pipeline_cache_bytes": ctx.pipeline_cache.loaded_bytes,
                       "config": config, "work": work, "stage": stage, "wall_ms": round(med["wall"], 2),
                       "gpu_ms": round(med["gpu"], 2), "host_ms": round(max(0.0, med["wall"] - med["gpu"]), 2),
                       "submits": int(med["submits"])}
                rows.append(row)
                print(f"{config:<16} {work:<14} {stage:<20} {row['wall_ms']:>9.2f} {row['gpu_ms']:>9.2f} "
                      f"{row['host_ms']:>9.2f} {row['submits']:>8}")
    append_csv(a.out or os.path.join(REPO, "docs", "bench", f"bake_stages_{device_label(info['device'])}.csv"), rows)


def device_label(name: str) -> str:
    name = name.lower()
    return "lavapipe" if "llvmpipe" in name else "nvidia-h200" if "h200" in name else \
        "nvidia-h100" if "h100" in name else name.split(" (")[0].replace(" ", "-")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--stages", action="store_true", help="per-stage wall beside GPU time (issue 38)")
    ap.add_argument("--ab", action="store_true", help="with --stages: each run also with the host paths issue 38 "
                                                      "replaced (before), alternating")
    ap.add_argument("--gpu-paths", action="store_true", help="with --stages on a CPU device: the code paths a GPU "
                                                             "takes where a bake picks by device")
    ap.add_argument("--out", default=None)
    ap.add_argument("--lighting", default="auto,volume", help="without --stages: which bakes (Lighting Auto's, "
                    "Lighting Volume's), each into its own CSV")
    ap.add_argument("--volume-out", default=None, help="the Volume rows' CSV (default "
                    "docs/bench/volume_bake_core_<device>.csv)")
    a = ap.parse_args()
    keep = hold_gpu_clock()  # noqa: F841 (the context holds the clock while it lives)
    info = {"device": "", "driver": ""}
    try:
        import pynvml
        pynvml.nvmlInit()
        info["driver"] = pynvml.nvmlSystemGetDriverVersion()
    except Exception:
        pass
    if a.stages:
        main_stages(a, info)
        return
    scene = read_scene(os.path.join(REPO, "samples", "room.ply"))
    r = SplatRenderer(scene)
    info["device"] = r.ctx.device_name
    label = device_label(info["device"])
    for name, bake in (("auto", auto_bake), ("volume", volume_bake)):
        if name not in a.lighting.split(","):
            continue
        with tempfile.TemporaryDirectory() as tmp:
            bake(r, scene, tmp)  # warm-up: pipelines, first allocations
            runs = [bake(r, scene, tmp) for _ in range(a.repeats)]
        med = {k: statistics.median(x[k] for x in runs) for k in runs[0] if isinstance(runs[0][k], float)}
        row = {"date": datetime.date.today().isoformat(), "device": info["device"], "driver": info["driver"],
               "sm_mhz": gpu_clock(), "load": round(os.getloadavg()[0], 2), "repeats": a.repeats,
               **{k: v for k, v in runs[0].items() if not isinstance(v, float)},  # Auto's choice, Volume's probes
               **{k: round(v, 4) for k, v in med.items()}}
        print(name, " ".join(f"{k}={v}" for k, v in row.items()))
        default = f"{name}_bake_core_{label}.csv"
        out = (a.out if name == "auto" else a.volume_out) or os.path.join(REPO, "docs", "bench", default)
        append_csv(out, [row])
    r.close()


if __name__ == "__main__":
    main()
