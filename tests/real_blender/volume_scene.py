"""The light volume in a real Blender (issue 37): run by tests/real_blender/test_volume_light.py inside a Blender
root with the built zip installed by Blender's installer, never by pytest itself:
    python volume_scene.py ARGS.json
1. The volume group against the core: the host's synthetic images (irr.npy, vis.npy, cells.npy, ARGS["spec"],
   ARGS["tiles"]) stored by the installed extension (lighting/volume.py store_volume); a unit sphere at the origin
   with the engine's volume group into an Emission, seen by an orthographic camera on +X; rendered in EEVEE and
   Cycles (group_<engine>.npy).
2. Motion: the sample room (Blender's PLY importer, native splats hidden from the camera), a white sphere keyframed
   over ARGS["path"] (one frame each), the probe at ARGS["probe"] with Lighting Volume: one bake; then at each frame
   an orthographic camera 3 m along +X of the sphere renders it in EEVEE (frame_<n>.npy); the file's atlases are
   saved (atlas_irr.npy, atlas_vis.npy, atlas_cells.npy, rows bottom first) with the spec, for the host's sample_packed.
3. Leaks: the host's two rooms (ARGS["rooms"]), Lighting Volume through the extension's own import and bake; the
   file's images saved (rooms_irr.npy, rooms_vis.npy, rooms_cells.npy) with the spec, for the host's sample_packed
   against the rooms' exact irradiance.
A line RESULT_TAG + JSON gives the reports and times.
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # blender_scene.py, copied beside this file
import blender_scene as bs  # noqa: E402
from blender_scene import MODULE  # noqa: E402

RESULT_TAG = "GSIBL-VOLUME-RESULT "
ARGS = json.load(open(sys.argv[1]))


def _ortho(name: str, scale: float, location) -> bpy.types.Object:
    cam = bpy.data.objects.get(name) or bpy.data.objects.new(name, bpy.data.cameras.new(name))
    if cam.name not in bpy.context.scene.objects:
        bpy.context.scene.collection.objects.link(cam)
    cam.data.type, cam.data.ortho_scale = "ORTHO", scale
    cam.rotation_euler = (math.pi / 2, 0.0, math.pi / 2)  # looks along -X; image right = +Y, up = +Z
    cam.location = location
    bpy.context.scene.camera = cam
    return cam


def _render(name: str, engine: str) -> float:
    scene = bpy.context.scene
    scene.render.engine = "CYCLES" if engine == "CYCLES" else bs.eevee_engine()
    scene.cycles.samples = ARGS["samples"]
    scene.eevee.taa_render_samples = ARGS["eevee_samples"]
    scene.render.filter_size = 0.0
    px, seconds = bs.render_still(os.path.join(ARGS["work"], f"{name}.exr"))
    np.save(os.path.join(ARGS["work"], f"{name}.npy"), px)
    return seconds


def _pixels(img) -> np.ndarray:
    w, h = img.size
    buf = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(buf)
    return buf.reshape(h, w, 4)[..., :3]


def _two_rooms(rec: dict, vn) -> None:
    """3. The leak scene (core/probe/volume_rooms.py, written by the host with its colour space) imported by our
    importer in a new scene, in the core's frame; a sphere in the dark room, a cube in the bright one, Lighting Volume
    at ARGS["rooms"]["probes"]: the file's three images and the spec saved for the host (rooms_*.npy)."""
    bs.clear()
    r = ARGS["rooms"]
    assert bpy.ops.gs_ibl.import_splats(filepath=r["ply"]) == {"FINISHED"}
    rooms = bpy.data.objects[os.path.splitext(os.path.basename(r["ply"]))[0]]
    rooms.location, rooms.rotation_euler, rooms.scale = (0, 0, 0), (0, 0, 0), (1, 1, 1)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=r["radius"], location=r["sphere"])
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=r["cube"])
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    probe = bs.add_probe(r["probe"], rooms, "GS-IBL Probe", keep_background=False, lighting="VOLUME",
                         volume_probes=r["probes"], face_size=32, irradiance_size=8)
    gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
    t0 = time.perf_counter()
    gb.bake_into_world(bpy.context.scene, probe)
    rec["times"]["rooms_bake"] = time.perf_counter() - t0
    rec["rooms_report"] = probe.gs_ibl_probe.local_report.splitlines()
    rec["rooms_colour_space"] = rooms.gs_ibl_splats.colour_space
    s = vn.volume_spec()
    rec["rooms_spec"] = {"lo": list(s.lo), "hi": list(s.hi), "shape": list(s.shape)}
    for key, img in (("irr", vn.volume_image()), ("vis", vn.visibility_image()), ("cells", vn.cells_image())):
        np.save(os.path.join(ARGS["work"], f"rooms_{key}.npy"), _pixels(img))


def main() -> dict:
    bs.enable_extension()
    vol = importlib.import_module(f"{MODULE}.blender.lighting.volume")
    vn = importlib.import_module(f"{MODULE}.blender.lighting.volume_nodes")
    ll = importlib.import_module(f"{MODULE}.blender.lighting.local_light")
    grid = importlib.import_module(f"{MODULE}.core.probe.grid")
    rec: dict = {"blender": bpy.app.version_string, "times": {}}
    try:
        bs.clear()
        bs.black_world()
        bs.reference_render_settings(ARGS["size"], ARGS["threads"])
        sp = ARGS["spec"]
        spec = grid.GridSpec(tuple(sp["lo"]), tuple(sp["hi"]), tuple(sp["shape"]))
        vol.store_volume(*(np.load(os.path.join(ARGS["work"], f"{k}.npy")) for k in ("irr", "vis", "cells")), spec,
                         ARGS["tiles"])
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
        sphere = bpy.context.active_object
        bpy.ops.object.shade_smooth()
        _ortho("cam", 2.4, (5.0, 0.0, 0.0))
        for engine in ("EEVEE", "CYCLES"):
            mat = bpy.data.materials.new(f"probe {engine}")
            mat.use_nodes = True
            nt = mat.node_tree
            nt.nodes.clear()
            geo, grp = nt.nodes.new("ShaderNodeNewGeometry"), nt.nodes.new("ShaderNodeGroup")
            grp.node_tree = vn.volume_group(engine)
            emit, out = nt.nodes.new("ShaderNodeEmission"), nt.nodes.new("ShaderNodeOutputMaterial")
            nt.links.new(geo.outputs["Position"], grp.inputs["Position"])
            nt.links.new(geo.outputs["Normal"], grp.inputs["Normal"])
            nt.links.new(grp.outputs["Irradiance"], emit.inputs["Color"])
            nt.links.new(emit.outputs[0], out.inputs["Surface"])
            sphere.data.materials.clear()
            sphere.data.materials.append(mat)
            rec["times"][f"group_{engine}"] = _render(f"group_{engine}", engine)
        # 2. motion in the sample room
        bs.clear()
        for kind in ("images", "node_groups"):
            for idb in list(getattr(bpy.data, kind)):
                getattr(bpy.data, kind).remove(idb)
        bs.black_world()
        scene = bpy.context.scene
        splats = bs.import_blender_ply(ARGS["ply"])
        splats.gs_ibl_splats.colour_space = "SRGB"
        mat = bs.white_material("White", ARGS["albedo"])
        ball = bs.sphere(ARGS["path"][0], ARGS["radius"], mat, "ball", segments=64, rings=32)
        scene.frame_start, scene.frame_end = 1, len(ARGS["path"])
        for f, loc in enumerate(ARGS["path"], 1):
            ball.location = loc
            ball.keyframe_insert("location", frame=f)
        scene.frame_set(1)
        probe = bs.add_probe(ARGS["probe"], splats, "GS-IBL Probe", keep_background=False, lighting="VOLUME")
        gb = importlib.import_module(f"{MODULE}.blender.lighting.bake")
        t0 = time.perf_counter()
        _, rec["bake_report"], rec["bake_warning"] = gb.bake_into_world(scene, probe)
        rec["times"]["bake"] = time.perf_counter() - t0
        rec["local_report"] = probe.gs_ibl_probe.local_report.splitlines()
        rec["ball_light"] = ll.has_local_light(ball)
        splats.visible_camera = False
        s = vn.volume_spec()
        rec["volume_spec"] = {"lo": list(s.lo), "hi": list(s.hi), "shape": list(s.shape)}
        np.save(os.path.join(ARGS["work"], "atlas_irr.npy"), _pixels(vn.volume_image()))
        np.save(os.path.join(ARGS["work"], "atlas_vis.npy"), _pixels(vn.visibility_image()))
        np.save(os.path.join(ARGS["work"], "atlas_cells.npy"), _pixels(vn.cells_image()))
        cam = _ortho("follow", ARGS["follow_scale"], (0.0, 0.0, 0.0))
        for f, loc in enumerate(ARGS["path"], 1):
            scene.frame_set(f)
            cam.location = (loc[0] + 3.0, loc[1], loc[2])
            rec["times"][f"frame_{f}"] = _render(f"frame_{f}", "EEVEE")
        if ARGS.get("rooms"):
            _two_rooms(rec, vn)
        rec["ok"] = True
    except Exception:  # noqa: BLE001 (reported to the host)
        rec.update(ok=False, error=traceback.format_exc())
    return rec


if __name__ == "__main__":
    print(RESULT_TAG + json.dumps(main()), flush=True)
