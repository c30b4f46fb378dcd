"""Blender 5.3's own importers make native Gaussian-splat Point Clouds; the installed extension bakes a probe from
each. Run by tests/real_blender/test_native_splats.py inside the bpy 5.3 root, never by pytest itself:
    python native_splats.py ARGS.json
ARGS: {"files": [[key, path, "ply" | "spz"], ...], "work": folder}. Per file it writes KEY.npz (the splats as our
reader sees the object, in world space, and the baked irradiance cube) and a line of RESULT_TAG + JSON on stdout.
It uses the extension as Blender installed it (bl_ext.user_default.gs_ibl), never this repository's gs_ibl_addon.
"""
from __future__ import annotations

import importlib
import json
import os
import sys
import time
import traceback

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # blender_scene.py, copied beside this file
import blender_scene as bs  # noqa: E402
from blender_scene import MODULE  # noqa: E402

RESULT_TAG = "GSIBL-NATIVE-RESULT "
ARGS = json.load(open(sys.argv[1]))


def main() -> dict:
    bs.enable_extension()
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    au = importlib.import_module(f"{MODULE}.blender.lighting.auto_update")
    core_bake = importlib.import_module(f"{MODULE}.core.bake")
    out = {"blender": bpy.app.version_string, "files": {}}
    for key, path, kind in ARGS["files"]:
        rec = out["files"][key] = {}
        try:
            bs.clear("objects")
            importer = bpy.ops.wm.ply_import if kind == "ply" else bpy.ops.wm.spz_import
            t0 = time.perf_counter()
            rec["import"] = sorted(importer(filepath=path))
            rec["import_s"] = time.perf_counter() - t0
            obj = bpy.context.active_object
            rec.update(type=obj.type, data_type=getattr(obj.data, "type", None), native=so.is_native_splats(obj),
                       splat_object=so.is_splat_object(obj), colour_space=so.colour_space_of(obj))
            world = so.scene_from_object(obj)
            probe_pos = core_bake.default_probe_position(world)
            probe = bs.add_probe(tuple(float(c) for c in probe_pos), obj, method="EXACT", face_size=64,
                                 irradiance_size=16, lighting="WORLD")
            s = probe.gs_ibl_probe
            t0 = time.perf_counter()
            result, text, warning = gb.bake_into_world(bpy.context.scene, probe)
            rec["bake_s"] = time.perf_counter() - t0
            rec.update(report=text, warning=warning, probe=probe_pos.tolist(),
                       world_is_ours=bpy.context.scene.world is not None
                       and bpy.context.scene.world.get("gs_ibl") == "world",
                       probe_colour_space=result.settings.get("colour_space"))
            np.savez(os.path.join(ARGS["work"], f"{key}.npz"), positions=world.positions, scales=world.scales,
                     rotations=world.rotations, opacities=world.opacities, sh=world.sh,
                     matrix=np.array(obj.matrix_world), irradiance=np.asarray(result.irradiance, np.float32))
            # the Linear rule is a push constant away: no second upload, a different light
            obj.gs_ibl_splats.colour_space = "LINEAR"
            linear, _, _ = gb.bake_into_world(bpy.context.scene, probe)
            rec["linear_over_srgb"] = float(np.mean(linear.irradiance) / np.mean(result.irradiance))
            # no double light: Cycles' bounces stop seeing the splats while our World carries their light
            rec["muted"] = [obj.visible_camera, obj.visible_diffuse, obj.visible_glossy]
            gw = importlib.import_module(f"{MODULE}.blender.lighting.world")
            rec["restored"] = [gw.restore_world(bpy.context.scene), obj.visible_diffuse, obj.visible_glossy]
            # Update When Moved with a native object: moving it notes one re-bake (timers do not run in the bpy
            # module, so the timer's function is called here as Blender's event loop would)
            s.auto_update = True
            n0 = au.auto_bakes
            obj.location.x += 0.1
            bpy.context.view_layer.update()
            noted = len(au._pending)
            au.run_pending()
            rec["auto"] = [noted, au.auto_bakes - n0]
            rec["ok"] = True
        except Exception:  # noqa: BLE001 (reported to the test, which fails on it)
            rec.update(ok=False, error=traceback.format_exc())
    return out


if __name__ == "__main__":
    print(RESULT_TAG + json.dumps(main()), flush=True)
