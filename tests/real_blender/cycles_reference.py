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
import math
import os
import sys
import time
import traceback

import bpy
import numpy as np
from mathutils import Matrix, Vector

RESULT_TAG = "GSIBL-CYCLES-RESULT "
MODULE = "bl_ext.user_default.gs_ibl"
ARGS = json.load(open(sys.argv[1]))


def _reset() -> None:
    for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.pointclouds, bpy.data.cameras, bpy.data.worlds,
                 bpy.data.materials, bpy.data.images):
        for block in list(coll):
            coll.remove(block)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("Black")
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    scene.world = world
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.threads_mode = "FIXED"
    r.threads = ARGS.get("threads", 2)
    scene.view_settings.view_transform = "Standard"  # EXR holds scene-linear values either way; said for clarity
    c = scene.cycles
    c.device = "CPU"
    c.use_denoising = False
    c.use_adaptive_sampling = False  # a fixed sample count: the noise the test states is the noise it gets
    c.seed = ARGS.get("seed", 0)
    c.max_bounces = c.diffuse_bounces = 4
    c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.transparent_max_bounces = 256  # a ray crosses several overlapping splats of the shell
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0  # no clamp: it would bias the bright splats
    c.filter_width = 0.01  # pixel centres, as our pinhole renders and as the test computes the sphere's normals


def _camera(cam: dict) -> bpy.types.Object:
    """A camera at cam["position"] looking at cam["look_at"], cam["up"] (default +Z) up, horizontal field of view
    cam["fov_deg"]: the geometry of core ViewBatch.pinhole (image right = forward x up)."""
    data = bpy.data.cameras.new("Reference Camera")
    data.sensor_fit = "HORIZONTAL"
    data.angle = math.radians(cam["fov_deg"])
    data.clip_start = 1e-3
    obj = bpy.data.objects.new("Reference Camera", data)
    bpy.context.collection.objects.link(obj)
    obj.location = cam["position"]
    forward = (Vector(cam["look_at"]) - Vector(cam["position"])).normalized()
    right = forward.cross(Vector(cam.get("up", (0.0, 0.0, 1.0)))).normalized()
    up = right.cross(forward)
    obj.rotation_mode = "QUATERNION"  # the camera looks down its -Z with +Y up
    obj.rotation_quaternion = Matrix((right, up, -forward)).transposed().to_quaternion()
    bpy.context.scene.camera = obj
    return obj


def _sphere(centre, radius: float) -> bpy.types.Object:
    bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=radius, location=centre)
    obj = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("White")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")  # Lambertian (roughness 0): outgoing radiance = albedo E / pi
    bsdf.inputs["Color"].default_value = (*(ARGS["albedo"],) * 3, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return obj


def _render(name: str, samples: int, size) -> tuple[np.ndarray, float]:
    """Render the scene's camera, film transparent; (H, W, 4) linear RGBA, top row first, and the wall seconds."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.cycles.samples = samples
    scene.render.film_transparent = True
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
    return px.reshape(h, w, 4)[::-1].copy(), seconds


def main() -> dict:
    import addon_utils
    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)
    gb = importlib.import_module(f"{MODULE}.blender.bake")
    so = importlib.import_module(f"{MODULE}.blender.splat_object")
    out = {"blender": bpy.app.version_string, "cases": {}}
    for case in ARGS["cases"]:
        key = case["key"]
        rec = out["cases"][key] = {}
        try:
            _reset()
            bpy.ops.wm.ply_import(filepath=case["ply"])  # Blender's importer: the reference owes nothing to ours
            splats = bpy.context.active_object
            rec.update(native=so.is_native_splats(splats), count=len(splats.data.points))
            splats.gs_ibl_splats.colour_space = case["colour_space"].upper()
            sphere = _sphere(ARGS["sphere"]["centre"], ARGS["sphere"]["radius"])
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
            bpy.ops.object.empty_add(location=ARGS["sphere"]["centre"])
            probe = bpy.context.active_object
            s = probe.gs_ibl_probe
            s.is_probe, s.splats = True, splats
            s.method, s.face_size, s.irradiance_size = "EXACT", ARGS["face_size"], 16
            s.lighting = "WORLD"  # the World probe against Cycles (Lighting Auto adds local light)
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
            bpy.ops.wm.ply_import(filepath=cap["ply"])
            splats = bpy.context.active_object
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
