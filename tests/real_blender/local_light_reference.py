"""One probe, per-object probes and a probe grid against Cycles path-tracing Blender's native splats: run by
tests/real_blender/test_local_light_reference.py inside the bpy 5.3 root, never by pytest itself:
    python local_light_reference.py ARGS.json
The sample room (its PLY encoded for Blender's sRGB rule) is imported by Blender's own PLY importer (a native
Gaussian-splat Point Cloud); white diffuse spheres stand in it. With the World black, Cycles renders each sphere lit
only by the native splats (the reference). Then the installed extension bakes the World probe at ARGS["probe"]
and each sphere is rendered lit by: our World alone ("one"), the World plus per-object probes ("object"), the World
plus a probe grid over ARGS["grid"] ("grid"); after a save and reload
("reloaded"), a grid over each sphere's own bounds ("fine"). Each render is saved as NAME.npy (H, W, 4, top row first); a line
RESULT_TAG + JSON gives times and reports. It uses the extension as Blender installed it, never this repository's.
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

RESULT_TAG = "GSIBL-LOCAL-RESULT "
ARGS = json.load(open(sys.argv[1]))


def _camera(cam: dict) -> None:
    bs.camera("cam", cam["position"], cam["look_at"], cam["fov_deg"])


def _render(name: str, samples: int) -> float:
    bpy.context.scene.cycles.samples = samples
    px, seconds = bs.render_still(os.path.join(ARGS["work"], f"{name}.exr"))
    np.save(os.path.join(ARGS["work"], f"{name}.npy"), px)
    return seconds


def _render_spheres(spheres: dict, tag: str, samples: int, rec: dict) -> None:
    """Each sphere alone in the picture (the others hidden from camera rays only: they still shadow and bounce)."""
    for name, obj in spheres.items():
        for other in spheres.values():
            other.visible_camera = other == obj
        _camera(ARGS["spheres"][name]["camera"])
        rec[f"{tag}_{name}_s"] = _render(f"{tag}_{name}", samples)
    for other in spheres.values():
        other.visible_camera = True


def main() -> dict:
    bs.enable_extension()
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    op = importlib.import_module(f"{MODULE}.blender.lighting.object_probes")
    pgrid = importlib.import_module(f"{MODULE}.blender.lighting.probe_grid")
    rec: dict = {"blender": bpy.app.version_string}
    try:
        bs.clear()
        bs.black_world()
        bs.reference_render_settings(ARGS["size"], ARGS.get("threads", 2))
        splats = bs.import_blender_ply(ARGS["ply"])
        rec["native"] = so.is_native_splats(splats)
        splats.gs_ibl_splats.colour_space = "SRGB"
        pos = so.scene_from_object(splats).positions
        rec["positions_head"] = pos[:64].tolist()  # the host checks Blender placed the file's splats as we do
        spheres = {name: bs.sphere(s["centre"], s["radius"], bs.white_material(f"White {name}", ARGS["albedo"]), name)
                   for name, s in ARGS["spheres"].items()}
        _render_spheres(spheres, "native", ARGS["native_samples"], rec)
        # what the camera sees of the native splats from each sphere's centre, all around (the spheres hidden):
        # the host compares its mean radiance with our probe's there
        for obj in spheres.values():
            obj.hide_render = True
        for name, sph in ARGS["spheres"].items():
            data = bpy.data.cameras.new("pano")
            data.type = "PANO"
            data.panorama_type = "EQUIRECTANGULAR"
            cam = bpy.data.objects.new("pano", data)
            bpy.context.collection.objects.link(cam)
            cam.location = sph["centre"]
            bpy.context.scene.camera = cam
            r = bpy.context.scene.render
            r.resolution_x, r.resolution_y = 2 * ARGS["pano_height"], ARGS["pano_height"]
            rec[f"pano_{name}_s"] = _render(f"pano_{name}", ARGS["pano_samples"])
            r.resolution_x = r.resolution_y = ARGS["size"]
        for obj in spheres.values():
            obj.hide_render = False
        # our light: the World probe, then per-object probes, then a grid
        # "one" is the World probe alone; local light is added below, by the operators
        probe = bs.add_probe(ARGS["probe"], splats, method="EXACT", face_size=ARGS["face_size"], irradiance_size=16,
                             keep_background=False, lighting="WORLD")
        s = probe.gs_ibl_probe
        t0 = time.perf_counter()
        _, rec["report"], rec["warning"] = gb.bake_into_world(bpy.context.scene, probe)
        rec["bake_s"] = time.perf_counter() - t0
        _render_spheres(spheres, "one", ARGS["samples"], rec)
        meshes = list(spheres.values())
        t0 = time.perf_counter()
        found, rec["variation"] = op.check_variation(bpy.context.scene, probe, meshes)
        rec["variation_s"] = time.perf_counter() - t0
        rec["variations"] = {v.name: v.variation for v in found}
        t0 = time.perf_counter()
        rec["object_report"] = op.bake_object_probes(bpy.context.scene, probe, meshes)
        rec["object_bake_s"] = time.perf_counter() - t0
        _render_spheres(spheres, "object", ARGS["samples"], rec)
        op.remove_local_light(bpy.context.scene, meshes)
        bpy.ops.object.empty_add(type="CUBE", location=ARGS["grid"]["centre"])
        region = bpy.context.active_object
        region.scale = ARGS["grid"]["half"]
        bpy.context.view_layer.update()  # matrix_world follows the new scale only once evaluated
        s.grid_region, s.grid_resolution = region, ARGS["grid"]["shape"]
        t0 = time.perf_counter()
        rec["grid_report"] = pgrid.bake_probe_grid(bpy.context.scene, probe, meshes)[0]
        rec["grid_bake_s"] = time.perf_counter() - t0
        _render_spheres(spheres, "grid", ARGS["samples"], rec)
        # saved and reloaded, the grid still lights the spheres as before
        path = os.path.join(ARGS["work"], "local.blend")
        bpy.ops.wm.save_as_mainfile(filepath=path)
        bpy.ops.wm.open_mainfile(filepath=path)
        spheres = {name: bpy.data.objects[name] for name in ARGS["spheres"]}
        _render_spheres(spheres, "reloaded", ARGS["samples"], rec)
        # a grid over each sphere's own bounds (Grid Region empty), both in the one atlas
        probe = next(o for o in bpy.data.objects if o.gs_ibl_probe.is_probe)
        probe.gs_ibl_probe.grid_region = None
        probe.gs_ibl_probe.grid_resolution = ARGS["fine_grid"]["shape"]
        op.remove_local_light(bpy.context.scene, [])
        t0 = time.perf_counter()
        rec["fine_report"] = pgrid.bake_probe_grid(bpy.context.scene, probe, list(spheres.values()))[0]
        rec["fine_bake_s"] = time.perf_counter() - t0
        _render_spheres(spheres, "fine", ARGS["samples"], rec)
        rec["ok"] = True
    except Exception:  # noqa: BLE001 (reported to the test, which fails on it)
        rec.update(ok=False, error=traceback.format_exc())
    return rec


if __name__ == "__main__":
    print(RESULT_TAG + json.dumps(main()), flush=True)
