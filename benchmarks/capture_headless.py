"""Run by the bpy 5.3 module (trixie root, benchmarks/capture_bench.py) with the built zip installed by Blender's
installer: one capture-sized PLY through the headless stages, each timed in this one process.

    python capture_headless.py ARGS.JSON        (ARGS: {"ply": path, "probe_move": 0.25})

  peer_import    Blender's own importer, bpy.ops.wm.ply_import (5.3 makes a Gaussian-splat Point Cloud of a 3DGS PLY)
  import_mesh    ours as a mesh (native=False: what Blender before 5.3 gets)
  import_native  ours as Blender's splats (native=True, the default on 5.3)
  bake           a probe at the centre of the native object, face size 0, Lighting World Probe
  rebake         the probe moved by probe_move metres, baked again

Every import is removed again (objects, meshes, point clouds) before the next, so one process holds one copy.
The file is read once before anything so every importer finds it in the page cache. Prints one line
"GSIBL-CAPTURE-HEADLESS {json}".
"""
from __future__ import annotations

import json
import os
import sys
import time
import traceback

import bpy

TAG = "GSIBL-CAPTURE-HEADLESS"
ARGS = json.load(open(sys.argv[1]))
MODULE = "bl_ext.user_default.gs_ibl"


def _clear() -> None:
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for coll in (bpy.data.meshes, getattr(bpy.data, "pointclouds", None)):
        if coll is None:
            continue
        for block in list(coll):
            if block.users == 0:
                coll.remove(block)


def _timed(rows: dict, name: str, fn) -> object:
    load = os.getloadavg()
    t0 = time.perf_counter()
    try:
        out = fn()
        rows[name] = {"s": time.perf_counter() - t0, "load": list(load), "ok": True, "result": str(out)[:300]}
    except Exception:  # noqa: BLE001  recorded, the next stage still runs where it can
        rows[name] = {"s": time.perf_counter() - t0, "load": list(load), "ok": False,
                      "error": traceback.format_exc()[-1500:]}
        out = None
    print(f"[capture_headless] {name}: {rows[name]['s']:.2f} s ok={rows[name]['ok']}", flush=True)
    return out


def _new_object(before: set[str]) -> bpy.types.Object:
    new = sorted(set(o.name for o in bpy.data.objects) - before)
    assert len(new) == 1, new
    return bpy.data.objects[new[0]]


def main() -> None:
    rows: dict = {}
    info = {"blender": bpy.app.version_string, "python": sys.version.split()[0], "ply": ARGS["ply"],
            "ply_bytes": os.path.getsize(ARGS["ply"])}
    try:
        import addon_utils
        if not addon_utils.check(MODULE)[1]:  # installed and enabled by the installer in this user directory
            bpy.ops.preferences.addon_enable(module=MODULE)
        info["enabled_by_prefs"] = addon_utils.check(MODULE)[1]
        _clear()
        with open(ARGS["ply"], "rb") as f:  # into the page cache: no importer pays the disk
            while f.read(64 << 20):
                pass
        ply = ARGS["ply"]

        before = set(o.name for o in bpy.data.objects)
        r = _timed(rows, "peer_import", lambda: bpy.ops.wm.ply_import(filepath=ply))
        if r is not None:
            obj = _new_object(before)
            info["peer_object"] = {"type": obj.type, "data": type(obj.data).__name__,
                                   "points": len(getattr(obj.data, "points", getattr(obj.data, "vertices", [])))}
        _clear()

        before = set(o.name for o in bpy.data.objects)
        r = _timed(rows, "import_mesh", lambda: bpy.ops.gs_ibl.import_splats(filepath=ply, axis_preset="BLENDER",
                                                                          native=False))
        if r is not None:
            obj = _new_object(before)
            info["mesh_object"] = {"type": obj.type, "verts": len(obj.data.vertices)}
        _clear()

        before = set(o.name for o in bpy.data.objects)
        r = _timed(rows, "import_native", lambda: bpy.ops.gs_ibl.import_splats(filepath=ply, axis_preset="BLENDER",
                                                                            native=True))
        obj = _new_object(before)
        info["native_object"] = {"type": obj.type, "data": type(obj.data).__name__}

        centre = [sum(c[i] for c in obj.bound_box) / 8 for i in range(3)]
        bpy.context.scene.cursor.location = centre
        bpy.ops.gs_ibl.add_probe(place="CURSOR")
        probe = bpy.context.active_object
        s = probe.gs_ibl_probe
        s.splats, s.lighting = obj, "WORLD"
        info["probe"] = {"at": centre, "face_size": s.face_size, "method": s.method, "lighting": s.lighting}

        def bake(name: str) -> str:
            s.last_report = ""
            r = bpy.ops.gs_ibl.bake_probe()
            assert r == {"FINISHED"} and s.last_report.startswith("Baked"), (r, s.last_report)
            return s.last_report

        _timed(rows, "bake", lambda: bake("bake"))
        probe.location.x += ARGS.get("probe_move", 0.25)
        bpy.context.view_layer.update()
        _timed(rows, "rebake", lambda: bake("rebake"))
        ok = all(r["ok"] for r in rows.values())
        error = None
    except Exception:  # noqa: BLE001
        ok, error = False, traceback.format_exc()
    print(f"{TAG} " + json.dumps({"ok": ok, "error": error, "rows": rows, "info": info}), flush=True)


main()
