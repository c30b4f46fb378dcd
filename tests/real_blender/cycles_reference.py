"""Blender's Cycles as the outside reference for our light: run by tests/real_blender/test_cycles_reference.py inside
the bpy 5.3 root, never by pytest itself:
    python cycles_reference.py ARGS.json
Per case (a colour space) it imports the case's 3DGS PLY with Blender's own importer (a native Gaussian-splat Point
Cloud, nothing of ours), then renders with Cycles on the CPU, denoiser off, World black:
  * sphere_KEY.npz: a white diffuse sphere lit only by the native splats (Cycles' bounce rays hitting them);
  * view_KEY.npz: the splats as the camera sees them (film transparent: alpha is their coverage);
  * world_KEY.npz: the same sphere lit by our World after the installed extension baked a probe at the sphere's
    centre from the same Point Cloud (which also mutes the splats' bounce visibility: no double light).
and prints RESULT_TAG + JSON (render seconds, the probe's irradiance lat-long range, errors).
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

RESULT_TAG = "GSIBL-CYCLES-RESULT "
ARGS = json.load(open(sys.argv[1]))


def _reset() -> None:
    """An empty scene, the World black, Cycles as the reference (blender_scene.reference_render_settings), and
    Cycles' own render of the native splats: Splats in Renders off (on, F12 draws the native splats with our
    renderer, the Native Splats default, and hides them from Cycles: the reference would be ours)."""
    bs.clear("objects", "meshes", "pointclouds", "cameras", "worlds", "materials", "images")
    bs.black_world()
    bs.reference_render_settings(threads=ARGS.get("threads", 2), seed=ARGS.get("seed", 0))
    bpy.context.scene.gs_ibl_render.enabled = False


def _camera(cam: dict) -> bpy.types.Object:
    """A camera at cam["position"] looking at cam["look_at"], cam["up"] (default +Z) up, horizontal field of view
    cam["fov_deg"]: the geometry of core ViewBatch.pinhole (image right = forward x up)."""
    return bs.camera("Reference Camera", cam["position"], cam["look_at"], cam["fov_deg"],
                     up=cam.get("up", (0.0, 0.0, 1.0)))


def _render(name: str, samples: int, size) -> tuple[np.ndarray, float]:
    """Render the scene's camera, film transparent; (H, W, 4) linear RGBA, top row first, and the wall seconds."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.cycles.samples = samples
    scene.render.film_transparent = True
    return bs.render_still(os.path.join(ARGS["work"], f"{name}.exr"))


def main() -> dict:
    bs.enable_extension()
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    out = {"blender": bpy.app.version_string, "cases": {}}
    for case in ARGS["cases"]:
        key = case["key"]
        rec = out["cases"][key] = {}
        try:
            _reset()
            splats = bs.import_blender_ply(case["ply"])  # Blender's importer: the reference owes nothing to ours
            rec.update(native=so.is_native_splats(splats), count=len(splats.data.points))
            splats.gs_ibl_splats.colour_space = case["colour_space"].upper()
            sphere = bs.sphere(ARGS["sphere"]["centre"], ARGS["sphere"]["radius"],
                               bs.white_material("White", ARGS["albedo"]))
            _camera(ARGS["sphere_camera"])
            px, rec["sphere_s"] = _render(f"sphere_{key}", ARGS["samples"], ARGS["size"])
            np.save(os.path.join(ARGS["work"], f"sphere_{key}.npy"), px)
            # the splats alone as the camera sees them (film transparent: alpha is coverage)
            sphere.hide_render = True
            _camera(ARGS["view_camera"])
            px, rec["view_s"] = _render(f"view_{key}", ARGS["view_samples"], ARGS["view_size"])
            np.save(os.path.join(ARGS["work"], f"view_{key}.npy"), px)
            # our light: a probe at the sphere's centre, baked from the same Point Cloud, lights it through our World
            sphere.hide_render = False
            _camera(ARGS["sphere_camera"])
            # the World probe against Cycles (Lighting Auto adds local light)
            probe = bs.add_probe(ARGS["sphere"]["centre"], splats, method="EXACT", face_size=ARGS["face_size"],
                                 irradiance_size=16, lighting="WORLD")
            t0 = time.perf_counter()
            result, rec["report"], rec["warning"] = gb.bake_into_world(bpy.context.scene, probe)
            rec["bake_s"] = time.perf_counter() - t0
            rec["muted"] = [splats.visible_camera, splats.visible_diffuse, splats.visible_glossy,
                            splats.visible_shadow]
            np.save(os.path.join(ARGS["work"], f"irradiance_{key}.npy"), np.asarray(result.irradiance, np.float32))
            px, rec["world_s"] = _render(f"world_{key}", ARGS["world_samples"], ARGS["size"])
            np.save(os.path.join(ARGS["work"], f"world_{key}.npy"), px)
            rec["ok"] = True
        except Exception:  # noqa: BLE001 (reported to the test, which fails on it)
            rec.update(ok=False, error=traceback.format_exc())
    for cap in ARGS.get("captures", []):
        rec = out["cases"][cap["key"]] = {}
        try:
            _reset()
            splats = bs.import_blender_ply(cap["ply"])
            rec.update(native=so.is_native_splats(splats), count=len(splats.data.points),
                       matrix=[list(r) for r in splats.matrix_world])
            _camera(cap["camera"])
            # a box filter of one pixel: each pixel the area average of the image, which our energy-preserving
            # dilation approximates splat by splat (pixel centres alone alias the capture's sub-pixel splats)
            bpy.context.scene.cycles.pixel_filter_type = "BOX"
            bpy.context.scene.cycles.filter_width = 1.0
            px, rec["view_s"] = _render(f"view_{cap['key']}", cap["samples"], cap["size"])
            np.save(os.path.join(ARGS["work"], f"view_{cap['key']}.npy"), px)
            rec["ok"] = True
        except Exception:  # noqa: BLE001
            rec.update(ok=False, error=traceback.format_exc())
    return out


if __name__ == "__main__":
    print(RESULT_TAG + json.dumps(main()), flush=True)
