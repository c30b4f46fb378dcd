#!/usr/bin/env python3
"""docs/img pictures of F12 frames: meshes standing in a splat capture, rendered by Cycles and by EEVEE with the
splats drawn by gs-ibl and composited with the meshes by depth (gs_ibl_addon/blender/render/).

Two captures: the bundled sample room (samples/room.ply) and the real guitar capture
(tests/data/guitar.compressed.ply). In each a white sphere and a grey Suzanne stand where some splats are in front of
them and others behind (the room's yellow and blue splat balls in front, the walls behind; the guitar in front of
Suzanne, the sphere in front of the guitar; a sun lamp lights the meshes by the guitar, whose capture holds nothing
around it; a blue World shows behind it, as F12 does unless Transparent is on). A probe by the meshes is baked
(Lighting Auto), then each engine renders the scene camera once; the time of that F12 (bpy.ops.render.render; the
splats' share from the render handler's record) goes to the caption line printed at the end and to --json.

    .venv/bin/python scripts/f12_pictures.py --out-dir docs/img [--json timings.json]    # the bpy module (5.0.1)

Writes OUT_DIR/blender_f12_<scene>_<engine>.png (480x270 by default). Small frames on purpose: on 2 shared CPU
cores (Cycles on the CPU, EEVEE and our renderer on Mesa llvmpipe/lavapipe) the four take about a minute.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import bpy
from mathutils import Vector

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for p in (ROOT, os.path.join(ROOT, "tests", "real_blender")):
    if p not in sys.path:
        sys.path.insert(0, p)

import blender_scene as bs  # noqa: E402 (camera, engine names: the helpers the real-Blender checks share)

ROOM = os.path.join(ROOT, "samples", "room.ply")
GUITAR = os.path.join(ROOT, "tests", "data", "guitar.compressed.ply")

# Per scene: the file and its import preset; the meshes (kind, location, size, rotation Z in degrees, grey);
# the probe; the camera (position, look-at, horizontal field of view in degrees).
SCENES = {
    "room": {
        "file": ROOM, "axes": "AUTO",  # the sample declares Z up
        # Suzanne on the table behind its yellow splat ball (the ball hides part of her), the sphere on the floor
        # behind the blue splat ball (likewise); the red wall and the floor behind both
        "meshes": [("monkey", (-1.3, -0.3, 1.1), 0.7, 90.0, 0.6),
                   ("sphere", (0.55, -1.3, 0.35), 0.35, 0.0, 0.8)],
        "probe": (-0.3, -0.9, 1.0),
        "camera": ((2.9, -0.5, 1.75), (-0.8, -0.7, 0.6), 72.0),
    },
    "guitar": {
        "file": GUITAR, "axes": "OPENCV",  # a 3DGS training output: y down (what Auto falls back to as well)
        "meshes": [("monkey", (-0.75, -1.0, 1.3), 1.3, 164.0, 0.55),
                   ("sphere", (0.95, 1.45, 0.42), 0.42, 0.0, 0.8)],
        "probe": (0.0, 0.8, 1.5),
        # the capture holds nothing around the guitar to light the meshes: a sun from the camera's upper left
        "sun": ((-4.0, 5.0, 6.0), 2.5),
        # a blue World (the GUI check's): F12 shows it behind the splats (Keep Background, the bake's default)
        "world": (0.1, 0.25, 0.8),
        "camera": ((2.2, 7.6, 2.0), (0.15, 0.0, 1.85), 58.0),
    },
}


def _args() -> argparse.Namespace:
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out-dir", default=os.path.join(ROOT, "docs", "img"))
    ap.add_argument("--scenes", default="room,guitar")
    ap.add_argument("--engines", default="cycles,eevee")
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    ap.add_argument("--cycles-samples", type=int, default=32)
    ap.add_argument("--eevee-samples", type=int, default=16)
    ap.add_argument("--face-size", type=int, default=128)
    ap.add_argument("--json", default=None, help="also write the timings here")
    return ap.parse_args(argv)


def _ensure_extension() -> None:
    """A Blender with the extension enabled has the operators; the bpy module (or a bare Blender) gets this copy."""
    try:
        bpy.ops.gs_ibl.bake_probe.get_rna_type()
    except (KeyError, AttributeError):
        import gs_ibl_addon
        gs_ibl_addon.register()


def _material(name: str, grey: float) -> bpy.types.Material:
    from gs_ibl_addon.blender.common.compat import node_tree
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in node_tree(mat).nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.5
    return mat


def build(name: str, face_size: int) -> dict:
    spec = SCENES[name]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _ensure_extension()
    assert bpy.ops.gs_ibl.import_splats(filepath=spec["file"], axis_preset=spec["axes"]) == {"FINISHED"}
    splats = bpy.context.active_object
    meshes = []
    for kind, location, size, rot_z, grey in spec["meshes"]:
        if kind == "sphere":
            bpy.ops.mesh.primitive_uv_sphere_add(radius=size, location=location, segments=64, ring_count=32)
        else:
            bpy.ops.mesh.primitive_monkey_add(size=size, location=location, rotation=(0.0, 0.0, math.radians(rot_z)))
            bpy.ops.object.modifier_add(type="SUBSURF")
        obj = bpy.context.active_object
        bpy.ops.object.shade_smooth()
        obj.data.materials.append(_material(f"{kind} grey {grey}", grey))
        meshes.append(obj)
    bpy.context.scene.cursor.location = spec["probe"]
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.splats = splats
    probe.gs_ibl_probe.face_size = face_size
    if "sun" in spec:
        towards, strength = spec["sun"]
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = strength
        sun.rotation_euler = (-Vector(towards)).to_track_quat("-Z", "Y").to_euler()  # a light shines down its -Z
        bpy.context.scene.collection.objects.link(sun)
    if "world" in spec:
        world = bpy.data.worlds.new("World")
        world.use_nodes = True
        bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
        bg.inputs["Color"].default_value = (*spec["world"], 1.0)
        bpy.context.scene.world = world
    position, look_at, fov = spec["camera"]
    cam = bs.camera("Camera", position, look_at, fov)
    cam.data.clip_end = 200.0
    scene = bpy.context.scene
    scene.view_settings.view_transform = "Standard"  # the capture's colours as captured
    t0 = time.perf_counter()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    bake_s = time.perf_counter() - t0
    print(f"[f12] {name}: bake {bake_s:.1f} s: {probe.gs_ibl_probe.last_summary}", flush=True)
    return {"splats": splats, "meshes": meshes, "probe": probe, "bake_s": bake_s}


def render(engine: str, path: str, args) -> dict:
    from gs_ibl_addon.blender.render import frame as render_frame
    scene = bpy.context.scene
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = args.width, args.height, 100
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGB"  # no alpha: the World shows behind the splats (Transparent off)
    if engine == "cycles":
        r.engine = "CYCLES"
        c = scene.cycles
        c.device, c.samples, c.max_bounces = "CPU", args.cycles_samples, 4
        try:
            import _cycles
            c.use_denoising = bool(getattr(_cycles, "with_openimagedenoise", False))
        except ImportError:
            c.use_denoising = False
        samples = c.samples
    else:
        r.engine = bs.eevee_engine()
        scene.eevee.taa_render_samples = args.eevee_samples
        samples = args.eevee_samples
    r.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    record = render_frame.last_render(scene)
    frame = record["frames"].get(scene.frame_current, {})
    out = {"engine": engine, "samples": samples, "seconds": round(seconds, 1), "splats": frame.get("splats"),
           "ms_splats": frame.get("ms_splats"), "ms_mesh_depth": frame.get("ms_mesh_depth"),
           "messages": record["messages"], "denoise": engine == "cycles" and scene.cycles.use_denoising}
    print(f"[f12] {os.path.basename(path)}: {out}", flush=True)
    return out


def main() -> None:
    args = _args()
    os.makedirs(args.out_dir, exist_ok=True)
    results = {"blender": bpy.app.version_string, "date": time.strftime("%Y-%m-%d"),
               "size": [args.width, args.height], "pictures": {}}
    for name in args.scenes.split(","):
        built = build(name, args.face_size)
        for engine in args.engines.split(","):
            path = os.path.abspath(os.path.join(args.out_dir, f"blender_f12_{name}_{engine}.png"))
            results["pictures"][os.path.basename(path)] = {"scene": name, "bake_s": round(built["bake_s"], 1),
                                                           **render(engine, path, args)}
    for png, rec in results["pictures"].items():
        spp = (f"{rec['samples']} spp" + (", denoised" if rec["denoise"] else "")) if rec["engine"] == "cycles" \
            else f"{rec['samples']} samples"
        print(f"[f12] caption {png}: {results['date']}, Blender {results['blender']}, "
              f"{'Cycles' if rec['engine'] == 'cycles' else 'EEVEE'}, {args.width}x{args.height}, {spp}, "
              f"{rec['seconds']} s per frame (splats {rec['ms_splats']} ms)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
