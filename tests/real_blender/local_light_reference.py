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
import math
import os
import sys
import time
import traceback

import bpy
import numpy as np
from mathutils import Vector

RESULT_TAG = "GSIBL-LOCAL-RESULT "
MODULE = "bl_ext.user_default.gs_ibl"
ARGS = json.load(open(sys.argv[1]))


def _setup() -> None:
    scene = bpy.context.scene
    for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.cameras, bpy.data.materials):
        for block in list(coll):
            coll.remove(block)
    world = bpy.data.worlds.new("Black")
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    scene.world = world
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x = r.resolution_y = ARGS["size"]
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.threads_mode, r.threads = "FIXED", ARGS.get("threads", 2)
    r.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    c = scene.cycles
    c.device, c.use_denoising, c.use_adaptive_sampling, c.seed = "CPU", False, False, 0
    c.max_bounces = c.diffuse_bounces = 4
    c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.transparent_max_bounces = 256
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.filter_width = 0.01


def _sphere(name: str, centre, radius: float) -> bpy.types.Object:
    bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=radius, location=centre)
    obj = bpy.context.active_object
    obj.name = name
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new(f"White {name}")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*(ARGS["albedo"],) * 3, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return obj


def _camera(cam: dict) -> None:
    data = bpy.data.cameras.new("cam")
    data.sensor_fit, data.angle, data.clip_start = "HORIZONTAL", math.radians(cam["fov_deg"]), 1e-3
    obj = bpy.data.objects.new("cam", data)
    bpy.context.collection.objects.link(obj)
    obj.location = cam["position"]
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = (Vector(cam["look_at"]) - Vector(cam["position"])).to_track_quat("-Z", "Y")
    bpy.context.scene.camera = obj


def _render(name: str, samples: int) -> float:
    scene = bpy.context.scene
    scene.cycles.samples = samples
    path = os.path.join(ARGS["work"], f"{name}.exr")
    scene.render.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    os.remove(path)
    np.save(os.path.join(ARGS["work"], f"{name}.npy"), px.reshape(h, w, 4)[::-1])
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
    import addon_utils
    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)
    gb = importlib.import_module(f"{MODULE}.blender.bake")
    so = importlib.import_module(f"{MODULE}.blender.splat_object")
    op = importlib.import_module(f"{MODULE}.blender.object_probes")
    pgrid = importlib.import_module(f"{MODULE}.blender.probe_grid")
    rec: dict = {"blender": bpy.app.version_string}
    try:
        _setup()
        bpy.ops.wm.ply_import(filepath=ARGS["ply"])
        splats = bpy.context.active_object
        rec["native"] = so.is_native_splats(splats)
        splats.gs_ibl_splats.colour_space = "SRGB"
        pos = so.scene_from_object(splats).positions
        rec["positions_head"] = pos[:64].tolist()  # the host checks Blender placed the file's splats as we do
        spheres = {name: _sphere(name, s["centre"], s["radius"]) for name, s in ARGS["spheres"].items()}
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
        bpy.ops.object.empty_add(location=ARGS["probe"])
        probe = bpy.context.active_object
        s = probe.gs_ibl_probe
        s.is_probe, s.splats = True, splats
        s.method, s.face_size, s.irradiance_size, s.keep_background = "EXACT", ARGS["face_size"], 16, False
        s.lighting = "WORLD"  # "one" is the World probe alone; local light is added below, by the operators
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
