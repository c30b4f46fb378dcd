#!/usr/bin/env python3
"""The README's main job, headless: splats -> probe -> bake -> meshes lit by the splats in a Cycles frame.

Builds a scene from the bundled sample environment (a room of ~22k splats with coloured walls, a bright window
and a ceiling lamp: core.synthetic.sample_environment, imported as a splat object through the PLY importer), adds
a probe and three meshes on the floor (a white diffuse sphere, a glossy metal sphere, a grey monkey), bakes,
renders a small Cycles frame to --out (PNG) and saves the .blend next to it (or to --blend).

    .venv/bin/python scripts/blender_demo.py --out docs/img/blender_demo.png          # bpy module
    blender -b --python scripts/blender_demo.py -- --out demo.png                     # a Blender binary

The splats are in the frame: gs-ibl draws them from the scene camera and composites them with the meshes by depth
(blender/render/: splats behind a mesh are hidden by it, splats in front of it hide it), and every mesh is lit by
the baked probe. The floor under the meshes is a shadow catcher, so their shadows darken the splat floor.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import bpy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from gs_ibl_addon.core.formats.axes import BLENDER_AXES, axes_comment  # noqa: E402
from gs_ibl_addon.core.formats.ply import write_ply  # noqa: E402
from gs_ibl_addon.core.synthetic import sample_environment  # noqa: E402

PROBE_AT = (0.0, 0.45, 0.4)


def _args() -> argparse.Namespace:
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="blender_demo.png", help="PNG to write")
    ap.add_argument("--blend", default=None, help=".blend to save (default: next to --out)")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--samples", type=int, default=48)
    ap.add_argument("--face-size", type=int, default=256,
                    help="probe face size (the camera sees the radiance map as the backdrop: give it detail)")
    ap.add_argument("--splats-png", default=None,
                    help="also write what the viewport overlay shows from the render camera (the splats alone)")
    return ap.parse_args(argv)


def _ensure_extension() -> None:
    """A Blender with the extension enabled has the operators; the bpy module (or a bare Blender) gets this copy."""
    try:
        bpy.ops.gs_ibl.bake_probe.get_rna_type()
    except (KeyError, AttributeError):
        import gs_ibl_addon
        gs_ibl_addon.register()


def _material(name: str, colour, metallic: float = 0.0, roughness: float = 0.5) -> bpy.types.Material:
    from gs_ibl_addon.blender.common.compat import node_tree
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in node_tree(mat).nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    return mat


def _add(kind: str, location, material, **kw) -> bpy.types.Object:
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(location=location, **kw)
    obj = bpy.context.active_object
    obj.data.materials.append(material)
    bpy.ops.object.shade_smooth()
    return obj


def build_scene(tmp: str, face_size: int = 256) -> tuple[bpy.types.Object, bpy.types.Object]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _ensure_extension()
    ply = os.path.join(tmp, "sample_environment.ply")
    write_ply(ply, sample_environment(), comments=(axes_comment(*BLENDER_AXES),))  # made Z up
    bpy.ops.gs_ibl.import_splats(filepath=ply)  # the default (Auto) reads the sample's declared axes: Z up
    splats = bpy.context.active_object
    splats.name = "Sample Environment"
    # A row of meshes on the floor (z = 0) in the open middle of the room, seen from its open side.
    _add("uv_sphere", (-0.85, 0.4, 0.35), _material("White Diffuse", (0.8, 0.8, 0.8), roughness=1.0),
         radius=0.35, segments=64, ring_count=32)
    _add("uv_sphere", (0.85, 0.4, 0.35), _material("Metal", (0.95, 0.93, 0.88), metallic=1.0, roughness=0.12),
         radius=0.35, segments=64, ring_count=32)
    monkey = _add("monkey", (0.0, 0.6, 0.4), _material("Grey", (0.35, 0.35, 0.35), roughness=0.6), size=0.75)
    monkey.rotation_euler = (math.radians(-20), 0.0, math.radians(-25))
    bpy.ops.object.modifier_add(type="SUBSURF")
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, 0.0))
    floor = bpy.context.active_object
    floor.name = "Shadow Catcher"
    floor.is_shadow_catcher = True  # shadows and contact on the backdrop; the floor itself is the probe's
    bpy.context.scene.cursor.location = PROBE_AT
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    bpy.context.view_layer.objects.active = None
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.splats = splats
    probe.gs_ibl_probe.face_size = face_size
    probe.gs_ibl_probe.keep_background = False
    return splats, probe


def setup_render(args) -> None:
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.data.lens = 24.0
    cam.location = (2.0, -1.6, 1.3)  # from the open side of the room: the table (x < -0.3) stays out of the way
    target = (-0.15, 0.55, 0.35)
    d = [t - c for t, c in zip(target, cam.location)]
    cam.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0, math.atan2(d[1], d[0]) - math.pi / 2)
    scene.camera = cam
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = args.width, args.height, 100
    r.image_settings.file_format = "PNG"
    r.filepath = os.path.abspath(args.out)
    c = scene.cycles
    c.device = "CPU"
    c.samples = args.samples
    c.max_bounces = 4
    try:
        import _cycles
        c.use_denoising = bool(getattr(_cycles, "with_openimagedenoise", False))
    except ImportError:
        c.use_denoising = False
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.exposure = 0.0


def write_splat_view(splats: bpy.types.Object, path: str, width: int, height: int) -> float:
    """The splats from the scene camera, rendered as the viewport overlay renders them (overlay_math), as a PNG."""
    import numpy as np
    from gs_ibl_addon.blender.viewport.overlay_images import overlay_for
    from gs_ibl_addon.core.image_io import write_png_preview
    cam = bpy.context.scene.camera
    window = np.array(cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=width, y=height))
    # the viewport overlay's own object: it draws with the renderer the bake already uploaded (splat_cache)
    img = overlay_for(splats).image(np.array(cam.matrix_world.inverted()), window, width, height)
    # a plain sRGB curve, one stop down (no AgX here): enough to see the room and the window
    write_png_preview(path, img.rgba[..., :3], exposure=-1.0)
    return img.render_ms


def main() -> None:
    args = _args()
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        splats, probe = build_scene(tmp, args.face_size)
        t_build = time.perf_counter() - t0
    setup_render(args)
    t0 = time.perf_counter()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    t_bake = time.perf_counter() - t0
    print("bake:", probe.gs_ibl_probe.last_report.replace("\n", " | "))
    os.makedirs(os.path.dirname(os.path.abspath(args.out)) or ".", exist_ok=True)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    t_render = time.perf_counter() - t0
    if args.splats_png:
        ms = write_splat_view(splats, args.splats_png, args.width, args.height)
        print(f"splats as the viewport overlay draws them: {ms:.0f} ms -> {os.path.abspath(args.splats_png)}")
    blend = os.path.abspath(args.blend or os.path.splitext(args.out)[0] + ".blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    data = splats.data  # a mesh, or in Blender 5.3+ a Gaussian-splat Point Cloud
    n_splats = len(data.points) if isinstance(data, getattr(bpy.types, "PointCloud", ())) else len(data.vertices)
    print(f"scene {t_build:.1f} s ({n_splats:,} splats), bake {t_bake:.1f} s, "
          f"Cycles {args.width}x{args.height} @ {args.samples} spp {t_render:.1f} s "
          f"(denoiser {'on' if bpy.context.scene.cycles.use_denoising else 'off'}), "
          f"total {time.perf_counter() - t_all:.1f} s")
    print(f"wrote {os.path.abspath(args.out)} and {blend}")


if __name__ == "__main__":
    main()
