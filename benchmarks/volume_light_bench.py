"""The whole bake's cost with Lighting Volume, Auto and World Probe, for 2, 3 and 10 meshes in the sample room
(issue 37's cost targets: three meshes <= 2x a World-Probe-only bake of the same probe, ten <= 4x, two in the GUI
<= 3 s).

Run:  .venv/bin/python benchmarks/volume_light_bench.py [--meshes 2,3,10] [--lightings AUTO,VOLUME,VOLUME]
      [--budget N] [--face N] [--no-write]
In the bpy module (.venv, Blender 5.0.1): the sample room imported by our importer, the probe at the room's centre
with the panel's defaults, then per mesh count a fresh scene's bakes in the order World Probe (its first bake reads
and uploads the splats: the cold number, not the peer), World Probe again (the peer: warm), Auto, Volume; each
whole bake timed around bpy.ops.gs_ibl.bake_probe() as the panel's button runs it. A lighting named twice is baked
twice (columns "_again"): Volume's first bake makes the volume's node groups, the next updates them. Every submission
is timestamped (the context's stamp_all), so each bake has its device time (the GPU's; on lavapipe the CPU's Vulkan
work) beside its wall, host = wall - device, and the seconds spent in the volume's node groups
(volume_nodes.build_groups). The meshes: spheres and
Suzannes at auto_light_bench's five places, the first N of them. The load average is printed with the table:
only ratios within one run mean anything on this shared 2-core machine. --budget / --face: a trial of the volume's
probe budget and cube face (blender/lighting/volume.py BUDGET, FACE; default the core's).
Writes docs/bench/volume_light_cost.csv and prints a markdown table.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
CSV = REPO / "docs" / "bench" / "volume_light_cost.csv"
SAMPLE = REPO / "samples" / "room.ply"


def _positions() -> list[tuple[str, tuple]]:
    from auto_light_bench import PLACES  # the accuracy bench's five places: one sphere and one Suzanne each
    out = []
    for kind, dx in (("sphere", 0.0), ("suzanne", 0.35)):
        for place, p in PLACES.items():
            c = p["centre"]
            out.append((f"{kind}_{place}", (c[0] + dx, c[1], c[2]), kind))
    return [out[i] for i in (0, 2, 3, 1, 4, 5, 6, 7, 8, 9)]  # the first three: centre, corner, table


def _scene(n: int):
    import bpy
    import gs_ibl_addon
    if hasattr(bpy.types.Object, "gs_ibl_probe"):  # the last count's scene: registered once at a time
        gs_ibl_addon.unregister()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    gs_ibl_addon.register()
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(SAMPLE), show_proxy=False) == {"FINISHED"}
    for name, loc, kind in _positions()[:n]:
        if kind == "sphere":
            bpy.ops.mesh.primitive_uv_sphere_add(radius=0.25, location=loc)
        else:
            bpy.ops.mesh.primitive_monkey_add(size=0.4, location=loc)
        bpy.context.active_object.name = name
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    bpy.context.scene.cursor.location = (0.0, 0.0, 1.2)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    return bpy.context.active_object


def _bake(probe, lighting: str) -> dict:
    """{"s": wall, "device_s", "host_s", "groups_s"} of one bake."""
    import bpy

    from gs_ibl_addon.blender.lighting import volume_nodes
    from gs_ibl_addon.core.vk.context import get_context
    probe.gs_ibl_probe.lighting = lighting
    bpy.context.view_layer.objects.active = probe
    ctx, build, groups = get_context(), volume_nodes.build_groups, [0.0]

    def timed(*args, **kwargs):
        t = time.perf_counter()
        try:
            return build(*args, **kwargs)
        finally:
            groups[0] += time.perf_counter() - t
    ctx.stamp_all, gpu0, volume_nodes.build_groups = True, ctx.stats.gpu_ms, timed
    try:
        t0 = time.perf_counter()
        assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
        wall = time.perf_counter() - t0
    finally:
        ctx.stamp_all, volume_nodes.build_groups = False, build
    device = (ctx.stats.gpu_ms - gpu0) / 1e3
    return {"s": round(wall, 2), "device_s": round(device, 2), "host_s": round(wall - device, 2),
            "groups_s": round(groups[0], 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", default="2,3,10")
    ap.add_argument("--lightings", default="AUTO,VOLUME,VOLUME")
    ap.add_argument("--budget", type=int, default=None)
    ap.add_argument("--face", type=int, default=None)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args()
    from gs_ibl_addon.blender.lighting import volume
    volume.BUDGET, volume.FACE = a.budget, a.face
    rows = []
    for n in (int(x) for x in a.meshes.split(",")):
        probe = _scene(n)
        cold = _bake(probe, "WORLD")["s"]
        world = _bake(probe, "WORLD")
        row = {"date": time.strftime("%Y-%m-%d"), "meshes": n, "world_cold_s": cold,
               **{f"world_{k}" if k != "s" else "world_s": v for k, v in world.items() if k != "groups_s"},
               "load": round(os.getloadavg()[0], 1)}
        for lighting in a.lightings.split(","):
            label = lighting.lower() if f"{lighting.lower()}_s" not in row else f"{lighting.lower()}_again"
            for k, v in _bake(probe, lighting).items():
                row[f"{label}_{k}" if k != "s" else f"{label}_s"] = v
            row[f"{label}_x_world"] = round(row[f"{label}_s"] / world["s"], 1)
            if lighting == "VOLUME":
                row["volume_report"] = probe.gs_ibl_probe.local_report.splitlines()[0]
        rows.append(row)
        print(row, flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    print("\n| " + " | ".join(keys) + " |\n|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(str(r.get(k, "")) for k in keys) + " |")
    if not a.no_write:
        CSV.parent.mkdir(parents=True, exist_ok=True)
        with open(CSV, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
        print(CSV)


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    main()
