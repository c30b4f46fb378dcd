"""Writing baked light into Blender: float lat-long images, the GS-IBL World, the irradiance node group.

Never touches what the user made: our images, World and node group carry the custom property ``gs_ibl``
(with a role, datablocks.py) and are found by it, not by name; a user's datablock of the same name is left alone
(ours then gets Blender's .001 suffix). Each probe has its own images and World (the probe remembers them); the
irradiance node group is one per file and follows the last bake. Images saved as files get names of ours
(``gs_ibl_<probe>_<role>.exr``) and never replace a file we did not write. scene.world changes only through
use_world(), which remembers the World it replaces so restore_world() can put it back.

Lat-long images follow core/cubemap.py (Blender's equirectangular mapping, top row = +Z); Blender stores
image rows bottom-up, so rows are flipped on the way in.
"""
from __future__ import annotations

import math
import os

import bpy
import numpy as np

from ..common.compat import node_tree
from ..common.datablocks import MARKER, find_ours, image_pixels, is_ours

WORLD_NAME = "GS-IBL World"
IRRADIANCE_GROUP = "GS-IBL Irradiance"
PREVIOUS_WORLD = "gs_ibl_previous_world"  # scene custom property: the World use_world() replaced
WRITTEN_FILE = "gs_ibl_file"  # image custom property: the EXR file we wrote for it (files we may overwrite)
RAY_VISIBILITY = "gs_ibl_ray_visibility"  # on a native splat object: its (diffuse, glossy) before we muted them


# ---------------------------------------------------------------------------------------------- images

def _abs(path: str) -> str:
    return os.path.normcase(os.path.abspath(bpy.path.abspath(path)))


def our_file_path(folder: str, stem: str, image: bpy.types.Image | None) -> str:
    """``folder/stem.exr``, or ``stem_1.exr``, ``stem_2.exr``, ...: the first that does not exist or that
    ``image`` itself was last written to. A file we did not write is never chosen (never overwritten)."""
    written = image.get(WRITTEN_FILE) if image is not None else None
    mine = _abs(written) if isinstance(written, str) else None
    i = 0
    while True:
        path = os.path.join(folder, f"{stem}_{i}.exr" if i else f"{stem}.exr")
        if not os.path.exists(path) or _abs(path) == mine:
            return path
        i += 1


def latlong_image(role: str, pixels: np.ndarray, name: str | None = None, pack: bool = True,
                  save_dir: str | None = None, image: bpy.types.Image | None = None,
                  file_stem: str | None = None) -> bpy.types.Image:
    """Our float image for ``role`` ("radiance", "irradiance", ...) from (H, W, 3) linear RGB.

    ``image``: our earlier image to update in place (ignored unless it is ours for ``role``); otherwise a new one.
    pack=True keeps it inside the .blend (as OpenEXR); otherwise it is saved as the EXR ``file_stem``.exr
    (default ``gs_ibl_<role>``; a suffix when a file of that name is not ours) in save_dir (default: next to the
    .blend, which must then be saved).
    """
    px = np.asarray(pixels, np.float32)
    if px.ndim != 3 or px.shape[2] not in (3, 4) or px.shape[1] != 2 * px.shape[0]:
        raise ValueError(f"lat-long image must be (H, 2H, 3) float, got {px.shape}")
    if not np.isfinite(px).all():
        raise ValueError(f"lat-long image for {role!r} contains NaN or infinite values")
    h, w = px.shape[:2]
    img = image if is_ours(image, role) else None
    if pack:
        if img is not None and (img.source != "GENERATED" or tuple(img.size) != (w, h) or not img.is_float):
            bpy.data.images.remove(img)
            img = None
        if img is None:
            img = bpy.data.images.new(name or f"GS-IBL {role.capitalize()}", w, h, alpha=False, float_buffer=True)
            img[MARKER] = role
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :3] = px[::-1, :, :3]  # Blender stores the bottom row first
        img.pixels.foreach_set(rgba.ravel())
        img.file_format = "OPEN_EXR"  # packs as a float EXR, not an 8-bit PNG
        img.pack()
    else:
        folder = save_dir or (bpy.path.abspath("//") if bpy.data.filepath else None)
        if not folder:
            raise ValueError("save the .blend first (baked images are written next to it), or pack the images")
        path = our_file_path(folder, bpy.path.clean_name(file_stem or f"gs_ibl_{role}"), img)
        _save_exr(path, px[..., :3])
        if img is None:
            img = bpy.data.images.load(path, check_existing=False)
            img.name = name or f"GS-IBL {role.capitalize()}"
            img[MARKER] = role
        else:
            if img.packed_file is not None:
                img.unpack(method="REMOVE")
            img.source = "FILE"
            img.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
            img.reload()
        # relative to the .blend, so moving the .blend with its images keeps them recognised as ours
        img[WRITTEN_FILE] = bpy.path.relpath(path) if bpy.data.filepath else path
    img.update()
    return img


def _save_exr(path: str, rgb: np.ndarray) -> None:
    """(H, W, 3) linear RGB, top row first, as a 32-bit float EXR written by Blender itself: not every Blender has
    OpenImageIO's Python module (the bpy 4.2 module has none).

    The image is marked as data (Non-Color) before its pixels are set: saved as "Linear Rec.709", Blender 5.0
    writes the EXR with an sRGB-like curve applied (0.5 -> 0.74) that only its own reader undoes; and setting the
    colour space after the pixels empties the buffer. Written under a temporary name and moved into place, so a
    failed save never leaves half a file."""
    h, w = rgb.shape[:2]
    tmp = bpy.data.images.new("gs_ibl_save", w, h, alpha=False, float_buffer=True)
    tmp.colorspace_settings.is_data = True
    part = f"{path}.part.exr"
    try:
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :3] = rgb[::-1]
        tmp.pixels.foreach_set(rgba.ravel())
        tmp.filepath_raw = part
        tmp.file_format = "OPEN_EXR"
        tmp.save()
        os.replace(part, path)
    finally:
        bpy.data.images.remove(tmp)
        if os.path.exists(part):
            os.remove(part)


def image_latlong_pixels(img: bpy.types.Image) -> np.ndarray:
    """Inverse of latlong_image: (H, W, 3) float, top row first."""
    return image_pixels(img)[::-1, :, :3].copy()


# ---------------------------------------------------------------------------------------------- World

def _background_output(world: bpy.types.World):
    """(World Output node, the socket that feeds its Surface) of a node World, or (None, None)."""
    nt = world.node_tree
    if nt is None:
        return None, None
    outs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    if out is None or not out.inputs["Surface"].links:
        return out, None
    return out, out.inputs["Surface"].links[0].from_socket


def build_world(radiance: bpy.types.Image, strength: float = 1.0, keep_background: bool = False,
                background_from: bpy.types.World | None = None,
                replace: bpy.types.World | None = None) -> bpy.types.World:
    """Our World lit by ``radiance``: a new one, or rebuilt in place of ``replace`` if that is a GS-IBL World
    (its users, e.g. scenes, follow; any other World is never replaced).

    keep_background: camera rays see ``background_from`` (a copy of its nodes, or its colour) instead of
    the probe, so the rendered backdrop stays as the user had it while everything else is lit by the probe.
    """
    old = replace if is_ours(replace, "world") else None
    if keep_background and background_from is not None and background_from.get(MARKER) != "world":
        world = background_from.copy()  # the user's World stays as it is; we edit the copy
    else:
        world = bpy.data.worlds.new(WORLD_NAME)
        if background_from is not None:
            world.color = background_from.color
    world[MARKER] = "world"
    if hasattr(world, "sun_threshold"):  # EEVEE 4.2+
        # no sun split off the probe's lamp and window: EEVEE then lights from the order-1 SH of the whole World,
        # which the local-light group models and corrects (core/probe/local_mix.py); a sun of the pixels above 10
        # lit our meshes from between the lamp and the window (measured 0.92-1.22 of Cycles' World light)
        world.sun_threshold = 0.0
    if hasattr(world, "cycles"):
        # Cycles' automatic importance map cost 1.5 s a render at 48x48 on 2 CPU cores, where a map as wide as
        # the radiance image (512 for the default bake) costs 0.08 s with the same noise (16 and 64 spp, measured
        # against 4,096 spp: 9.66/3.38% vs 9.58/3.25%)
        world.cycles.sampling_method = "MANUAL"
        world.cycles.sample_map_resolution = int(min(max(radiance.size[0], 256), 2048))
    nt = node_tree(world)
    out, prev_shader = _background_output(world)
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputWorld")
    if not keep_background:
        for n in list(nt.nodes):
            if n != out:
                nt.nodes.remove(n)
        prev_shader = None
    elif prev_shader is None:  # a World without nodes feeding the output: use its colour
        bg_prev = nt.nodes.new("ShaderNodeBackground")
        bg_prev.inputs["Color"].default_value = (*world.color, 1.0)
        prev_shader = bg_prev.outputs["Background"]
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.name = env.label = "GS-IBL Radiance"
    env.image = radiance
    env.interpolation = "Linear"
    env.projection = "EQUIRECTANGULAR"
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.name = bg.label = "GS-IBL Strength"
    bg.inputs["Strength"].default_value = strength
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    env.location = out.location.x - 650, out.location.y - 300
    bg.location = out.location.x - 350, out.location.y - 300
    if keep_background:
        path = nt.nodes.new("ShaderNodeLightPath")
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.name = mix.label = "GS-IBL Keep Background"
        # Fac 0 -> first shader (probe light), Fac 1 -> second (what the camera saw before)
        nt.links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
        nt.links.new(bg.outputs["Background"], mix.inputs[1])
        nt.links.new(prev_shader, mix.inputs[2])
        nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
        path.location, mix.location = (out.location.x - 350, out.location.y + 250), (out.location.x - 150,
        out.location.y)
    else:
        nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    if old is not None and old != world:
        old.user_remap(world)
        bpy.data.worlds.remove(old)
    world.name = WORLD_NAME
    return world


def set_world_strength(world: bpy.types.World, strength: float) -> None:
    node = world.node_tree.nodes.get("GS-IBL Strength") if world.node_tree else None
    if node is not None:
        node.inputs["Strength"].default_value = strength


def use_world(scene: bpy.types.Scene, world: bpy.types.World) -> None:
    """Make ``world`` the scene's World, remembering the one it replaces (unless that is ours)."""
    current = scene.world
    if current is not None and current != world and current.get(MARKER) != "world":
        scene[PREVIOUS_WORLD] = current
    scene.world = world


def restore_world(scene: bpy.types.Scene) -> bool:
    """Put back the World that use_world() replaced (and the native splats' bounce light); False if there is none
    to restore."""
    prev = scene.get(PREVIOUS_WORLD)
    if not isinstance(prev, bpy.types.World):
        return False
    unmute_native_splats(scene)
    scene.world = prev
    del scene[PREVIOUS_WORLD]
    return True


# ---------------------------------------------------------------------------------------------- no double light

def native_splats_in(scene: bpy.types.Scene) -> list[bpy.types.Object]:
    from ..splats.object import is_native_splats
    return [o for o in scene.objects if is_native_splats(o)]


def mute_native_splats(scene: bpy.types.Scene) -> list[str]:
    """Blender 5.3's native splats stop lighting meshes through Cycles' diffuse and glossy bounces while our World
    carries their light (it would count twice), and stop casting shadows: our World already stands for the light
    they let through, and shadow rays blocked by them took 20-35% of it in Cycles (tests/real_blender/
    test_cycles_reference.py). Camera rays still see them. Each object keeps what it had (RAY_VISIBILITY) for
    unmute_native_splats. Returns the names of the objects changed now."""
    changed = []
    for obj in native_splats_in(scene):
        if RAY_VISIBILITY not in obj.keys():
            obj[RAY_VISIBILITY] = [int(obj.visible_diffuse), int(obj.visible_glossy), int(obj.visible_shadow)]
            obj.visible_diffuse = obj.visible_glossy = obj.visible_shadow = False
            changed.append(obj.name)
    return changed


def unmute_native_splats(scene: bpy.types.Scene) -> list[str]:
    """Give native splats back the bounce visibility mute_native_splats took."""
    changed = []
    for obj in scene.objects:
        saved = obj.get(RAY_VISIBILITY)
        if saved is not None:
            obj.visible_diffuse, obj.visible_glossy = bool(saved[0]), bool(saved[1])
            if len(saved) > 2:  # files saved before shadows were muted kept two
                obj.visible_shadow = bool(saved[2])
            del obj[RAY_VISIBILITY]
            changed.append(obj.name)
    return changed


# ---------------------------------------------------------------------------------------------- node group

def irradiance_group(image: bpy.types.Image) -> bpy.types.ShaderNodeTree:
    """Shader node group: our irradiance lat-long looked up along the world-space shading normal.

    Outputs "Irradiance" (E(n)/pi times Strength: a white Lambertian surface's outgoing radiance) and
    "Diffuse" (an Emission shader of Albedo x Irradiance: the thesis's fast diffuse path, no ray tracing).
    The lookup: latlong_lookup.
    """
    tree = find_ours(bpy.data.node_groups, "irradiance")
    if tree is None:
        tree = bpy.data.node_groups.new(IRRADIANCE_GROUP, "ShaderNodeTree")
        tree[MARKER] = "irradiance"
        # No material uses it until the user adds it: without a fake user it would vanish on save.
        tree.use_fake_user = True
        _build_irradiance_tree(tree)
    tree.nodes["GS-IBL Irradiance Image"].image = image
    return tree


def latlong_lookup(tree, normal, image: bpy.types.Image | None, name: str = "GS-IBL Irradiance Image"):
    """Nodes in ``tree`` that read our lat-long ``image`` along the world-space direction ``normal`` (a socket);
    returns the colour socket. The lookup of core/cubemap.py in math nodes:
    u = 0.5 - atan2(y, x) / 2pi,  v (bottom-up) = 1 - acos(z) / pi."""
    N, L = tree.nodes, tree.links
    sep = N.new("ShaderNodeSeparateXYZ")
    L.new(normal, sep.inputs[0])

    def op(name, a, b=None, x=0):
        m = N.new("ShaderNodeMath")
        m.operation = name
        m.location = (x, 0)
        for i, v in enumerate((a, b)):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                m.inputs[i].default_value = v
            else:
                L.new(v, m.inputs[i])
        return m.outputs[0]

    az = op("ARCTAN2", sep.outputs["Y"], sep.outputs["X"])  # atan2(A, B)
    u = op("MULTIPLY_ADD", az, -1.0 / (2.0 * math.pi), x=200)
    u.node.inputs[2].default_value = 0.5
    zc = op("MINIMUM", op("MAXIMUM", sep.outputs["Z"], -1.0), 1.0)
    polar = op("ARCCOSINE", zc)
    v = op("MULTIPLY_ADD", polar, -1.0 / math.pi, x=200)
    v.node.inputs[2].default_value = 1.0
    comb = N.new("ShaderNodeCombineXYZ")
    L.new(u, comb.inputs["X"])
    L.new(v, comb.inputs["Y"])
    tex = N.new("ShaderNodeTexImage")
    tex.name = tex.label = name
    tex.image = image
    tex.interpolation = "Linear"
    tex.extension = "REPEAT"  # wraps the azimuth seam
    L.new(comb.outputs[0], tex.inputs["Vector"])
    return tex.outputs["Color"]


def albedo_strength_inputs(iface) -> None:
    """The Albedo (0.8 grey) and Strength (1) inputs our diffuse node groups share."""
    alb = iface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    alb.default_value = (0.8, 0.8, 0.8, 1.0)
    st = iface.new_socket("Strength", in_out="INPUT", socket_type="NodeSocketFloat")
    st.default_value, st.min_value = 1.0, 0.0


def _build_irradiance_tree(tree: bpy.types.ShaderNodeTree) -> None:
    iface = tree.interface
    albedo_strength_inputs(iface)
    iface.new_socket("Diffuse", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("Irradiance", in_out="OUTPUT", socket_type="NodeSocketColor")
    N, L = tree.nodes, tree.links
    gin, gout = N.new("NodeGroupInput"), N.new("NodeGroupOutput")
    geo = N.new("ShaderNodeNewGeometry")
    colour = latlong_lookup(tree, geo.outputs["Normal"], None)
    scaled = N.new("ShaderNodeVectorMath")
    scaled.operation = "SCALE"
    L.new(colour, scaled.inputs[0])
    L.new(gin.outputs["Strength"], scaled.inputs["Scale"])
    diffuse = N.new("ShaderNodeVectorMath")
    diffuse.operation = "MULTIPLY"
    L.new(scaled.outputs[0], diffuse.inputs[0])
    L.new(gin.outputs["Albedo"], diffuse.inputs[1])
    emit = N.new("ShaderNodeEmission")
    L.new(diffuse.outputs[0], emit.inputs["Color"])
    L.new(emit.outputs[0], gout.inputs["Diffuse"])
    L.new(scaled.outputs[0], gout.inputs["Irradiance"])
    gout.location = (1400, 0)

