"""Run by the bpy 5.3 module (trixie root) with the "after" zip installed (benchmarks/capture_bench.py --thread-check):
is a bake slower on a jobs.Runner's worker thread than run inline, without any UI? (A trial: its answer, no, is in
docs/benchmarks.md's "Capture-sized scenes".)

    python capture_thread_check.py ARGS.JSON        (ARGS: {"ply": path, "repeats": 3})

Our native import of the file, a probe at its centre (Lighting World Probe, face size 0), one bake to upload the
splats, then ``repeats`` re-bakes each way, alternating: ``inline`` (jobs.run_now: what execute() and blender -b
do) and ``worker`` (jobs.Runner ticked every 0.1 s from this thread, which sleeps in between, as a modal operator's
timer does). Per bake: wall seconds, the core's report line, and this process's CPU seconds. Prints one line
"GSIBL-CAPTURE-THREAD {json}".
"""
from __future__ import annotations

import importlib
import json
import os
import sys
import time
import traceback

import bpy

TAG = "GSIBL-CAPTURE-THREAD"
ARGS = json.load(open(sys.argv[1]))
MODULE = "bl_ext.user_default.gs_ibl"


def main() -> None:
    out: dict = {"runs": []}
    try:
        import addon_utils
        if not addon_utils.check(MODULE)[1]:
            bpy.ops.preferences.addon_enable(module=MODULE)
        jobs = importlib.import_module(f"{MODULE}.blender.common.jobs")
        gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
        for obj in list(bpy.data.objects):
            bpy.data.objects.remove(obj)
        assert bpy.ops.gs_ibl.import_splats(filepath=ARGS["ply"], axis_preset="BLENDER", native=True) == {"FINISHED"}
        splats = bpy.context.active_object
        bpy.context.scene.cursor.location = [sum(c[i] for c in splats.bound_box) / 8 for i in range(3)]
        bpy.ops.gs_ibl.add_probe(place="CURSOR")
        probe = bpy.context.active_object
        probe.gs_ibl_probe.splats, probe.gs_ibl_probe.lighting = splats, "WORLD"
        scene = bpy.context.scene
        t0 = time.perf_counter()
        jobs.run_now(gb.bake_job(scene, probe, splats))
        out["first_bake_s"] = time.perf_counter() - t0
        for k in range(ARGS.get("repeats", 3)):
            for how in ("inline", "worker"):
                probe.location.x += 0.05 if k % 2 else -0.05
                bpy.context.view_layer.update()
                load = os.getloadavg()[0]
                c0, t0 = time.process_time(), time.perf_counter()
                if how == "inline":
                    jobs.run_now(gb.bake_job(scene, probe, splats))
                else:
                    r = jobs.Runner(gb.bake_job(scene, probe, splats), "baking")
                    while not r.tick():
                        time.sleep(jobs.TICK_S)
                    if r.error is not None:
                        raise r.error
                wall = time.perf_counter() - t0
                report = probe.gs_ibl_probe.last_report
                core = next((x for x in report.splitlines() if x.startswith("render ")), report[:200])
                out["runs"].append({"how": how, "wall_s": wall, "process_cpu_s": time.process_time() - c0,
                                    "load1": load, "core": core})
                print(f"[thread_check] {how}: {wall:.2f} s, CPU {time.process_time() - c0:.2f} s, load {load:.2f}; "
                      f"{core[:90]}", flush=True)
        out["ok"] = True
    except Exception:  # noqa: BLE001
        out.update(ok=False, error=traceback.format_exc())
    print(f"{TAG} " + json.dumps(out), flush=True)


main()
