"""The Blender side of benchmarks/auto_light_bench.py (issue 22 goal 2): run inside the bpy 5.3 root, with the
built zip installed by Blender's own installer, never by this repository's Python:
    python auto_light_scene.py ARGS.json
The sample room (its PLY encoded for Blender's sRGB rule, as tests/real_blender/local_light_reference.py does) is
imported by Blender's own PLY importer (a native Gaussian-splat Point Cloud) and hidden from the camera (film
transparent: alpha masks the mesh). A white diffuse UV sphere and a Suzanne (albedo ARGS["albedo"], smooth shaded,
one material) stand at each of ARGS["places"]; each is rendered alone (every other mesh hidden from the render) from
its own camera:
  native_<mesh>_<place>          Cycles, World black, lit only by the native splats (the reference);
  world_<engine>_<mesh>_<place>  our probe at ARGS["probe"] with Lighting "World Probe", Cycles and EEVEE;
  auto_<engine>_<mesh>_<place>   the same probe with Lighting "Auto" (each mesh measured and given its light).
Each render is saved as NAME.npy (H, W, 4, top row first); one line RESULT_TAG + JSON gives times, the bake
reports, Auto's choice per mesh and what a World-Probe bake after an Auto one leaves on the meshes. It uses the
extension as Blender installed it, never this repository's.
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # blender_scene.py, copied beside this file
import blender_scene as bs  # noqa: E402 (tests/real_blender/blender_scene.py)
from blender_scene import MODULE  # noqa: E402

RESULT_TAG = "GSIBL-AUTO-BENCH "
ARGS = json.load(open(sys.argv[1]))


def _setup() -> None:
    bs.clear()
    bs.black_world()
    bs.reference_render_settings(ARGS["size"], ARGS["threads"])
    for key, value in ARGS.get("cycles_settings", {}).items():  # a trial of Cycles' own options (every render)
        setattr(bpy.context.scene.cycles, key, value)


def _mesh(kind: str, place: str, mat: bpy.types.Material) -> bpy.types.Object:
    p = ARGS["places"][place]
    centre = Vector(p["centre"])
    if kind == "sphere":
        obj = bs.sphere(centre, ARGS["radius"], mat, f"{kind}_{place}", segments=96, rings=48)
    else:
        bpy.ops.mesh.primitive_monkey_add(size=ARGS["suzanne_size"], location=centre)
        obj = bpy.context.active_object
        obj.name = f"{kind}_{place}"
        bpy.ops.object.shade_smooth()
        obj.data.materials.append(mat)
        to_cam = Vector(p["camera"]) - centre
        obj.rotation_euler = (0.0, 0.0, math.atan2(to_cam.y, to_cam.x) + math.pi / 2)  # its face (-Y) to the camera
        mod = obj.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = 1
    bpy.context.view_layer.update()
    if p.get("rest_on") is not None:  # resting on a surface at this height (the table top)
        zmin = min((obj.matrix_world @ Vector(c)).z for c in obj.bound_box)
        obj.location.z += p["rest_on"] + 0.005 - zmin
        bpy.context.view_layer.update()
    return obj


def _camera(place: str) -> None:
    p = ARGS["places"][place]
    name = f"cam_{place}"
    obj = bpy.data.objects.get(name)
    if obj is None:
        obj = bs.camera(name, p["camera"], p["centre"], ARGS["fov_deg"])
    bpy.context.scene.camera = obj


def _render(name: str, engine: str, samples: int) -> float:
    scene = bpy.context.scene
    scene.render.engine = "CYCLES" if engine == "CYCLES" else bs.eevee_engine()
    if engine == "CYCLES":
        scene.cycles.samples = samples
    else:
        scene.eevee.taa_render_samples = samples
        for key, value in ARGS.get("eevee_settings", {}).items():  # a trial of EEVEE's own options
            setattr(scene.eevee, key, value)
    px, seconds = bs.render_still(os.path.join(ARGS["work"], f"{name}.exr"))
    np.save(os.path.join(ARGS["work"], f"{name}.npy"), px)
    print(f"[auto-bench] {name}: {seconds:.1f} s", flush=True)
    return seconds


def _each(meshes: dict, fn) -> None:
    """fn(key) with the mesh ``key`` alone in the render (every other mesh hidden: no shadow, no bounce); in an
    animation at the key's frame, seen by the camera on the path."""
    for key, obj in meshes.items():
        for other in meshes.values():
            other.hide_render = other is not obj
        if ARGS.get("animation"):
            _at_frame(key)
        else:
            _camera(key[1])
        fn(key)
    for other in meshes.values():
        other.hide_render = False
    if ARGS.get("animation"):
        bpy.context.scene.frame_set(1)


def _animate(meshes: dict, anim: dict) -> dict:
    """Issue 37's animation: every mesh keyframed (linear) from place anim["from"] at frame 1 to anim["to"] at
    anim["frames"], a camera moving from the first place's camera to the second's and tracking an Empty on the same
    path. Returns {(kind, "fNN"): mesh} for the frames anim["at"] (cells() and the renders key on these)."""
    scene = bpy.context.scene
    a, b = (ARGS["places"][anim[k]] for k in ("from", "to"))
    last = int(anim["frames"])
    scene.frame_start, scene.frame_end = 1, last
    target = bpy.data.objects.new("path_target", None)
    bpy.context.collection.objects.link(target)
    cam = bs.camera("cam_path", a["camera"], a["centre"], ARGS["fov_deg"])
    track = cam.constraints.new("TRACK_TO")
    track.target, track.track_axis, track.up_axis = target, "TRACK_NEGATIVE_Z", "UP_Y"
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"  # an even move (any Blender's API)
    for obj in [*meshes.values(), target]:
        start = Vector(obj.location) if obj is not target else Vector(a["centre"])
        for frame, loc in ((1, start), (last, start + Vector(b["centre"]) - Vector(a["centre"]))):
            obj.location = loc
            obj.keyframe_insert("location", frame=frame)
    for frame, loc in ((1, a["camera"]), (last, b["camera"])):
        cam.location = loc
        cam.keyframe_insert("location", frame=frame)
    scene.frame_set(1)
    return {(kind, f"f{f:02d}"): obj for (kind, _place), obj in meshes.items() for f in anim["at"]}


def _at_frame(key) -> None:
    """The frame of an animation key ("fNN"), the camera that follows the path."""
    bpy.context.scene.frame_set(int(key[1][1:]))
    bpy.context.scene.camera = bpy.data.objects["cam_path"]


def main() -> dict:
    bs.enable_extension()
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    so = importlib.import_module(f"{MODULE}.blender.splats.object")
    ll = importlib.import_module(f"{MODULE}.blender.lighting.local_light")
    rec: dict = {"blender": bpy.app.version_string, "times": {}}
    times = rec["times"]
    steps = ARGS["steps"]
    try:
        _setup()
        splats = bs.import_blender_ply(ARGS["ply"])
        rec["native"] = so.is_native_splats(splats)
        splats.gs_ibl_splats.colour_space = "SRGB"
        splats.visible_camera = False  # the mesh alone in the picture; bounce and shadow rays still see the splats
        rec["positions_head"] = so.scene_from_object(splats).positions[:64].tolist()
        mat = bs.white_material("White", ARGS["albedo"])
        anim = ARGS.get("animation")
        places = [anim["from"]] if anim else ARGS["places"]
        meshes = {(kind, place): _mesh(kind, place, mat) for place in places for kind in ARGS["meshes"]}
        if anim:
            meshes = _animate(meshes, anim)
        rec["boxes"] = {f"{k[0]}_{k[1]}": [list(map(float, o.matrix_world @ Vector(c))) for c in o.bound_box]
                        for k, o in meshes.items()}

        def name(tag, key):
            return f"{tag}_{key[0]}_{key[1]}"

        if "native" in steps:
            _each(meshes, lambda k: times.__setitem__(name("native", k), _render(name("native", k), "CYCLES",
                                                                                 ARGS["native_samples"])))
        if not {"world", "auto", "volume"} & set(steps):
            rec["ok"] = True
            return rec
        probe = bs.add_probe(ARGS["probe"], splats, "GS-IBL Probe", keep_background=False)  # panel's defaults else
        s = probe.gs_ibl_probe

        def ours(tag: str) -> None:
            def one(k):
                times[name(f"{tag}_cycles", k)] = _render(name(f"{tag}_cycles", k), "CYCLES", ARGS["samples"])
                times[name(f"{tag}_eevee", k)] = _render(name(f"{tag}_eevee", k), "EEVEE", ARGS["eevee_samples"])
            if "eevee_first_s" not in times:  # EEVEE's first frame compiles its shaders: not a frame's cost
                (_at_frame if ARGS.get("animation") else lambda k: _camera(k[1]))(next(iter(meshes)))
                times["eevee_first_s"] = _render("eevee_warmup", "EEVEE", 1)
            _each(meshes, one)

        if "world" in steps:
            s.lighting = "WORLD"
            t0 = time.perf_counter()
            _, rec["world_report"], rec["world_warning"] = gb.bake_into_world(bpy.context.scene, probe)
            times["world_bake_s"] = time.perf_counter() - t0
            splats.visible_camera = False
            ours("world")
        if "auto" in steps:
            s.lighting = "AUTO"
            t0 = time.perf_counter()
            _, rec["auto_report"], rec["auto_warning"] = gb.bake_into_world(bpy.context.scene, probe)
            times["auto_bake_s"] = time.perf_counter() - t0
            splats.visible_camera = False
            rec["local_report"] = s.local_report.splitlines()
            rec["last_report"] = s.last_report.splitlines()
            rec["choice"] = {f"{k[0]}_{k[1]}": ll.has_local_light(o) or "world" for k, o in meshes.items()}
            ours("auto")
            # the EEVEE warm-up compiled the World Probe's material; Auto's adds the local-light group: its
            # first frame compiles again, so the first auto EEVEE frame's time holds that
        if "volume" in steps:  # Lighting Volume (issue 37): one volume over every mesh, shared
            s.lighting = "VOLUME"
            volume = importlib.import_module(f"{MODULE}.blender.lighting.volume")
            volume.BUDGET, volume.FACE = ARGS.get("volume_budget"), ARGS.get("volume_face")  # None: the core's
            t0 = time.perf_counter()
            _, rec["volume_report"], rec["volume_warning"] = gb.bake_into_world(bpy.context.scene, probe)
            times["volume_bake_s"] = time.perf_counter() - t0
            splats.visible_camera = False
            rec["volume_local_report"] = s.local_report.splitlines()
            rec["volume_choice"] = {f"{k[0]}_{k[1]}": ll.has_local_light(o) or "world" for k, o in meshes.items()}
            ours("volume")
        if "auto" in steps:
            # Lighting back to World Probe and baked again (warm): what stays on the meshes?
            s.lighting = "WORLD"
            t0 = time.perf_counter()
            gb.bake_into_world(bpy.context.scene, probe)
            times["world_rebake_warm_s"] = time.perf_counter() - t0
            rec["after_world_rebake"] = {f"{k[0]}_{k[1]}": ll.has_local_light(o) for k, o in meshes.items()}
            rec["after_world_rebake_group_in_material"] = ll.in_material(mat)
        rec["ok"] = True
    except Exception:  # noqa: BLE001 (reported to the driver)
        rec.update(ok=False, error=traceback.format_exc())
    return rec


if __name__ == "__main__":
    print(RESULT_TAG + json.dumps(main()), flush=True)
