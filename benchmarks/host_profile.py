"""Where a bake's host time goes (issues 37 and 38): cProfile of the warm bakes on one uploaded renderer.

Run: python benchmarks/host_profile.py [--works default,auto,camera,volume] [--repeats 5] [--top 25] [--out DIR]
     python benchmarks/host_profile.py --copy-ab [--repeats 30]

The pieces of work are auto_bake_core.py --stages' (the sample's default bake, Lighting Auto's bake of the sphere,
a 1920x1080 camera frame) and volume_bench.py's cost run (Lighting Volume's bake for three meshes). Each is run
once to warm up, then --repeats times under the profiler with no submission timestamped (as a user's bake runs).
Prints, per work, the wall time per run and the functions with the most time of their own and the most time under
them; with --out, one .pstats file per work (``python -m pstats``). On a GPU the functions are the host time; on
lavapipe the rendering is host time too, so read the GPU machine's table.

``--copy-ab``: the camera frame's wall time, not profiled, with host copies on one thread and on vk/buffers.py's
COPY_THREADS (and 4), alternating in one process (medians of --repeats), the GPU's clock held.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from auto_bake_core import PROBE, REPO, sphere_auto  # noqa: E402
from volume_bench import COST_SETS, boxes_of  # noqa: E402

from gs_ibl_addon.core.bake import ProbeSettings, bake_probe, default_probe_position  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe.volume_refine import bake_light_volume  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402


def works(r: SplatRenderer, scene) -> dict:
    """{name: the work, a function of no arguments}."""
    def default() -> None:
        bake_probe(None, default_probe_position(scene), ProbeSettings(), renderer=r, host_splats=scene)

    def auto() -> None:
        bake_probe(None, PROBE, ProbeSettings(), renderer=r, host_splats=scene)
        sphere_auto(r)

    cam = np.eye(4)
    cam[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    cam[:3, 3] = PROBE
    view = ViewBatch.camera(cam, np.tan(np.radians(30)), np.tan(np.radians(30)) * 1080 / 1920, 1920, 1080)

    def camera() -> None:
        r.render_camera(view)

    def volume() -> None:
        bake_light_volume(r, boxes_of(COST_SETS["3 meshes"]))

    return {"default": default, "auto": auto, "camera": camera, "volume": volume}


def copy_ab(camera, repeats: int) -> None:
    """--copy-ab: the camera frame's wall ms per copy-thread count, alternating."""
    from bench_common import gpu_clock, hold_gpu_clock
    from gs_ibl_addon.core.vk import buffers
    keep, default = hold_gpu_clock(), buffers.COPY_THREADS  # noqa: F841 (the CUDA context holds the clock)
    walls: dict[int, list[float]] = {n: [] for n in dict.fromkeys((1, 4, default))}
    try:
        for _ in range(repeats):
            for n, w in walls.items():
                buffers.COPY_THREADS = n
                t0 = time.perf_counter()
                camera()
                w.append((time.perf_counter() - t0) * 1e3)
    finally:
        buffers.COPY_THREADS = default
    print(f"camera 1920x1080, SM {gpu_clock()} MHz, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}")
    for n, w in walls.items():
        print(f"copy threads {n}: wall ms median {statistics.median(w):.2f}, min {min(w):.2f}, max {max(w):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--works", default="default,auto,camera,volume")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--out", default=None, help="a folder for one .pstats file per work")
    ap.add_argument("--copy-ab", action="store_true", help="the camera frame's wall by copy threads, not profiled")
    a = ap.parse_args()
    scene = read_scene(os.path.join(REPO, "samples", "room.ply"))
    r = SplatRenderer(scene)
    r.ctx.stamp_all = False
    print(f"device: {r.ctx.device_name}")
    table = works(r, scene)
    if a.copy_ab:
        for _ in range(3):
            table["camera"]()  # warm-up
        copy_ab(table["camera"], a.repeats)
        r.close()
        return
    for name in a.works.split(","):
        fn = table[name]
        fn()  # warm-up: pipelines, allocations, cached plans
        prof = cProfile.Profile()
        walls = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            prof.enable()
            fn()
            prof.disable()
            walls.append((time.perf_counter() - t0) * 1e3)
        print(f"\n=== {name}: wall ms per run (profiled) {' '.join(f'{w:.1f}' for w in walls)}")
        for key in ("tottime", "cumulative"):
            s = io.StringIO()
            pstats.Stats(prof, stream=s).strip_dirs().sort_stats(key).print_stats(a.top)
            text = s.getvalue()
            print(f"--- {name}, by {key} (seconds over {a.repeats} runs)")
            print(text[text.find("   ncalls"):].rstrip())
        if a.out:
            os.makedirs(a.out, exist_ok=True)
            prof.dump_stats(os.path.join(a.out, f"{name}.pstats"))
    r.close()


if __name__ == "__main__":
    main()
