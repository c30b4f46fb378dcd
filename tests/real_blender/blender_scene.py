"""The scenes and the Blender set-up that the real-Blender checks (tests/real_blender/*_reference.py,
native_splats.py) and the benchmarks run in a real Blender (benchmarks/auto_light_scene.py, native_bench.py) share,
instead of each copying them.

Two halves, one file, importable on both sides:
- on this machine (pytest, a benchmark's driver): numpy, and gs_ibl_addon.core imported inside the function;
  write_room_for_blender, sphere_pixels, block_ratios, mesh_mask.
- inside a real Blender, with the built zip installed by Blender's installer: the functions that import bpy when
  called (never at import, so that the host never loads the bpy module by importing this file). They use bpy,
  what Blender ships (numpy) and the extension as Blender installed it (MODULE), never this repository's.
  test_matrix.run_script copies this file beside the script it runs; a script that copies itself (native_bench.py)
  copies this file too. The script imports it from its own folder: ``python script.py`` puts that folder first on
  sys.path, and the scripts put it there themselves for ``blender --python script.py``.

Each works in every Blender of the matrix (4.2 to 5.3): a new material or World has its node tree only on request
before 5.0, and it is requested only then.
"""
from __future__ import annotations

import os
import time

import numpy as np

MODULE = "bl_ext.user_default.gs_ibl"  # the extension as Blender's installer puts it in the user_default repository

# The white diffuse sphere in the sample room (samples/room.ply's own Z-up frame) that the matrix's scenario, the
# native-splats benchmark and its core bake (benchmarks/auto_bake_core.py) light: a probe at its centre.
ROOM_SPHERE = {"centre": (0.0, 0.45, 1.0), "radius": 0.3}
ALBEDO = 0.8


# ------------------------------------------------------------------------------------------- on this machine

def write_room_for_blender(path, room_ply=None):
    """samples/room.ply (linear colours) written to ``path`` with its colours encoded for Blender's sRGB rule
    (Blender decodes every splat as sRGB, so it gets the room's linear light); returns the scene written (positions
    as our reader reads the file)."""
    from gs_ibl_addon.core.colour import linear_sh_for_srgb_rule
    from gs_ibl_addon.core.formats import read_scene
    from gs_ibl_addon.core.formats.ply import write_ply
    if room_ply is None:
        room_ply = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "samples", "room.ply")
    room = read_scene(room_ply)
    assert room.colour_space == "linear"
    room.sh = linear_sh_for_srgb_rule(room.sh)
    room.colour_space = "srgb"  # what Blender does with any splat: the file declares nothing
    write_ply(path, room)
    return room


def sphere_pixels(cam: dict, centre, radius: float, width: int, height: int | None = None, grazing: float = 0.35):
    """Per pixel of the pinhole camera ``cam`` ({"position", "look_at", "fov_deg"}, +Z up; top row first): the
    sphere's unit normal where the pixel's centre ray meets it, and a mask of the pixels well inside its outline
    (the cosine between the normal and the way back to the camera above ``grazing``: their footprint wholly on the
    sphere)."""
    from gs_ibl_addon.core.render.views import ViewBatch
    batch = ViewBatch.pinhole(cam["position"], cam["look_at"], cam["fov_deg"], width, height or width)
    d = batch.views[0].pixel_directions()
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.asarray(cam["position"], np.float64) - np.asarray(centre, np.float64)
    b = d @ o
    disc = b * b - (o @ o - radius ** 2)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    n = (o + t[..., None] * d) / radius
    return n, (disc > 0) & (-(n * d).sum(-1) > grazing)


def block_ratios(got: np.ndarray, want: np.ndarray, mask: np.ndarray, k: int) -> np.ndarray:
    """Per screen block (k x k over the bounds of the ``mask``ed pixels; a block of fewer than 20 of them is left
    out) and channel: mean(got) / mean(want) - 1 over the block's masked pixels."""
    ys, xs = np.nonzero(mask)
    ye = np.linspace(ys.min(), ys.max() + 1, k + 1).astype(int)
    xe = np.linspace(xs.min(), xs.max() + 1, k + 1).astype(int)
    out = []
    for i in range(k):
        for j in range(k):
            sel = np.zeros_like(mask)
            sel[ye[i]:ye[i + 1], xe[j]:xe[j + 1]] = True
            sel &= mask
            if sel.sum() >= 20:
                out.append(got[sel].mean(0) / want[sel].mean(0) - 1.0)
    return np.array(out)


def mesh_mask(*renders, erode: int = 1) -> np.ndarray:
    """Pixels covered (alpha > 0.999) in every render (H, W, 4), ``erode`` pixels in from the outline: each engine's
    own pixel filter stays out (numpy only: used on both sides)."""
    m = np.logical_and.reduce([r[..., 3] > 0.999 for r in renders])
    for _ in range(erode):
        e = m.copy()
        e[1:] &= m[:-1]
        e[:-1] &= m[1:]
        e[:, 1:] &= m[:, :-1]
        e[:, :-1] &= m[:, 1:]
        m = e
    return m


# ------------------------------------------------------------------------------------------------- in Blender

def enable_extension() -> None:
    """The installed extension enabled (the installer enabled it in the user's preferences; the bpy module may
    start without them)."""
    import addon_utils
    import bpy
    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)


def clear(*kinds: str) -> None:
    """Every data-block of bpy.data's collections ``kinds`` removed (default: objects, meshes, cameras, materials)."""
    import bpy
    for kind in kinds or ("objects", "meshes", "cameras", "materials"):
        coll = getattr(bpy.data, kind)
        for block in list(coll):
            coll.remove(block)


def black_world(name: str = "Black"):
    """A new World giving no light (black, strength 0), made the scene's: the splats alone light the meshes."""
    import bpy
    world = bpy.data.worlds.new(name)
    if world.node_tree is None:  # before Blender 5.0 the tree is made only on request
        world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    bpy.context.scene.world = world
    return world


def reference_render_settings(size=None, threads: int = 2, seed: int = 0) -> None:
    """Cycles as an outside reference (the engine set; EEVEE's own settings left as they are): on the CPU, a fixed
    sample count (no adaptive sampling), denoiser off, no clamp (it would bias the bright splats), up to 4 diffuse
    bounces and none glossy, 256 transparent bounces (a ray crosses many overlapping splats), a filter of pixel
    centres (0.01 px: as our pinhole renders and as the checks compute a sphere's normals); 32-bit EXR stills, a
    transparent film (alpha masks the meshes), view transform Standard, ``threads`` threads; ``size``: the frame,
    square (an int) or (width, height), at 100% (None: left as it is)."""
    import bpy
    scene = bpy.context.scene
    r = scene.render
    r.engine = "CYCLES"
    if size is not None:
        r.resolution_x, r.resolution_y = (size, size) if isinstance(size, int) else size
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.threads_mode, r.threads = "FIXED", threads
    r.film_transparent = True
    scene.view_settings.view_transform = "Standard"  # EXR holds scene-linear values either way; said for clarity
    c = scene.cycles
    c.device, c.use_denoising, c.use_adaptive_sampling, c.seed = "CPU", False, False, seed
    c.max_bounces = c.diffuse_bounces = 4
    c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.transparent_max_bounces = 256
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.filter_width = 0.01


def eevee_engine() -> str:
    """EEVEE's identifier in this Blender (BLENDER_EEVEE_NEXT in 4.2-4.x, BLENDER_EEVEE from 5.0)."""
    import bpy
    ids = {i.identifier for i in bpy.context.scene.render.bl_rna.properties["engine"].enum_items}
    return next(e for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE") if e in ids)


def white_material(name: str = "White", albedo: float = ALBEDO):
    """A diffuse (Lambertian: roughness 0, outgoing radiance = albedo E / pi) grey material of ``albedo``."""
    import bpy
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # before Blender 5.0 the tree is made only on request
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def sphere(centre, radius: float, material, name: str | None = None, segments: int = 128, rings: int = 64):
    """A smooth-shaded UV sphere at ``centre`` with ``material``, the active object."""
    import bpy
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius, location=centre)
    obj = bpy.context.active_object
    if name is not None:
        obj.name = name
    bpy.ops.object.shade_smooth()
    obj.data.materials.append(material)
    return obj


def camera(name: str, position, look_at, fov_deg: float, up=None):
    """A new camera ``name`` at ``position`` looking at ``look_at`` (horizontal field of view ``fov_deg``, clip
    start 1 mm), linked to the active collection and made the scene's camera. ``up`` None: its image's up as near
    world +Z as it goes (to_track_quat); else the image's right = forward x ``up`` (core ViewBatch.pinhole's
    geometry)."""
    import math

    import bpy
    from mathutils import Matrix, Vector
    data = bpy.data.cameras.new(name)
    data.sensor_fit, data.angle, data.clip_start = "HORIZONTAL", math.radians(fov_deg), 1e-3
    obj = bpy.data.objects.new(name, data)
    bpy.context.collection.objects.link(obj)
    obj.location = position
    obj.rotation_mode = "QUATERNION"  # the camera looks down its -Z with +Y up
    if up is None:
        obj.rotation_quaternion = (Vector(look_at) - Vector(position)).to_track_quat("-Z", "Y")
    else:
        forward = (Vector(look_at) - Vector(position)).normalized()
        right = forward.cross(Vector(up)).normalized()
        obj.rotation_quaternion = Matrix((right, right.cross(forward), -forward)).transposed().to_quaternion()
    bpy.context.scene.camera = obj
    return obj


def import_blender_ply(path: str):
    """``path`` imported by Blender's own PLY importer (5.3: a native Gaussian-splat Point Cloud of a 3DGS PLY,
    nothing of ours); the new object."""
    import bpy
    bpy.ops.wm.ply_import(filepath=path)
    return bpy.context.active_object


def add_probe(location, splats, name: str | None = None, **settings):
    """An empty at ``location`` (named ``name``) made our probe (is_probe) of ``splats``, then its gs_ibl_probe
    ``settings`` set in the order given (method, face_size, lighting, ...: the panel's defaults for the rest); the
    probe object."""
    import bpy
    bpy.ops.object.empty_add(location=location)
    probe = bpy.context.active_object
    if name is not None:
        probe.name = name
    s = probe.gs_ibl_probe
    s.is_probe, s.splats = True, splats
    for key, value in settings.items():
        setattr(s, key, value)
    return probe


def read_image(path: str, top_first: bool = True) -> np.ndarray:
    """An image file as Blender loads it: (H, W, 4) float32, top row first (Blender's pixels run bottom up)."""
    import bpy
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    px = px.reshape(h, w, 4)
    return px[::-1].copy() if top_first else px


def render_still(path: str, keep: bool = False, top_first: bool = True) -> tuple[np.ndarray, float]:
    """The scene's camera rendered to ``path`` (the scene's file format): the pixels (read_image) and the wall
    seconds of the render call; the file is removed unless ``keep``."""
    import bpy
    bpy.context.scene.render.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    px = read_image(path, top_first)
    if not keep:
        os.remove(path)
    return px, seconds
