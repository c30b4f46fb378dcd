"""The material node group through which a mesh gets light of its own: a per-object probe or a probe grid.

The World (one probe) keeps lighting every mesh: background, specular and diffuse. A mesh whose light differs
from the World probe's gets it through its material:

    surface = s x the user's shader + Emission(albedo x strength x (H(n) - s B(n)))          (EEVEE)
    surface = s x the user's shader + (1 - s) x Diffuse(albedo) + Emission(... (H(n) - B(n)))  (Cycles)

where H is the mesh's light (the World probe's plus D, the mesh's difference: its own probe, or its grid at the
shading point), B what the user's shader gets from the World in this engine and s the largest scale in 0..1 that
keeps H - s B non-negative (EEVEE clamps negative emission; Cycles keeps it, so there the emission is H - B and the
World's diffuse stays traced): core/probe/local_mix.py is the numpy twin and says why. The emission is also scaled
by the mesh's own ambient occlusion (Only Local): the engines shadow the user's shader, not emission (in Cycles its
square where the emission adds light, which is mostly one-directional there; docs/accuracy.md). The group has
two outputs, one per engine, read by the user's Material Output and by an EEVEE-only output of ours: Cycles H = E +
D over B = E (the World probe's irradiance image), EEVEE H = W + D over its order-1 part of W (the World probe's
order-2 coefficients) as EEVEE derings it. Irradiance is order-2 SH, kept as the nine monomial coefficients of
core/probe/grid.py, so each of W and D is a sum of nine colours times polynomials of the normal.

Every kind of local light is a grid (a per-object probe is a 1 x 1 x 1 grid at the mesh's centre), and every grid
is a tile (core/probe/grid.py ``pack_grid``) of one float image per file, the atlas, stacked from the bottom
row up. A mesh says which tile and where its box is through four custom properties (GRID_ATTRS), read by
Attribute nodes of type Object (EEVEE reads at most 8 such attributes per material: these are 4), so one
material serves meshes with different grids, and a mesh without them (sharing the material) reads 0 and keeps
the World's light. Per coefficient the 8 texels around the point, blended trilinearly. W lives on the atlas
(WORLD_COEFFS) and in the group as constants.

One group per file (rebuilt when the atlas changes); inserting it into a material puts one group node between
the user's shader and the Material Output, and one EEVEE Material Output of ours beside it;
``remove_from_material`` links them directly again and deletes only our nodes, so nothing of the user's material
is lost. The state lives in datablocks (custom properties, the packed atlas and its tile list, the group), so it
follows undo and save/reload.
"""
from __future__ import annotations

import json

import bpy
import numpy as np

from ...core.probe.grid import COEFFS, GridSpec
from ...core.probe.local_mix import EPS, eevee_world_order1
from ..common.compat import node_tree
from ..common.datablocks import MARKER, find_ours, image_pixels, is_ours, packed_float_image
from .node_math import NodeMath as _Nodes
from .world import albedo_strength_inputs, latlong_lookup

GROUP_NAME = "GS-IBL Local Light"
ROLE = "local_light"
GRID_KEY = "gs_ibl_grid_key"  # object custom property: its tile of the atlas ("probe:...", "object:...", ...)
# what the shader reads of the object's grid: box corner, (n - 1) / span, n - 1, (1, first row in the atlas, 0)
GRID_ATTRS = {"lo": "gs_ibl_grid_lo", "scale": "gs_ibl_grid_scale", "max": "gs_ibl_grid_max",
              "tile": "gs_ibl_grid_tile"}
VOLUME_KEY = "volume"  # GRID_KEY of a mesh the file's light volume lights (blender/lighting/volume.py)
VOLUME_ATTR = "gs_ibl_volume"  # object custom property read by the group: 1 where the light volume lights the mesh
TILES = "gs_ibl_tiles"  # atlas custom property: JSON {key: {"lo", "hi", "shape", "row0"}}
WORLD_COEFFS = "gs_ibl_world"  # atlas custom property: JSON (9, 3) monomial coefficients of the World probe's light
WORLD_IRRADIANCE = "gs_ibl_world_irradiance"  # atlas custom property: the World probe's irradiance image (E/pi)
AO_SAMPLES = 4  # Cycles' rays per shading point for the correction's occlusion (its samples average them)
AO_DISTANCE = 1.0  # metres
AO_LIT_POWER = 2.0  # Cycles: the AO stand-in's power on light the mesh adds (D > 0); 1 on light it takes away
EEVEE_OUTPUT = "GS-IBL EEVEE Output"  # our Material Output (target EEVEE) in a lit material
GRID_IMAGE = "GS-IBL Grid"
DEFAULT_MATERIAL_ROLE = "local_material"


def set_object_grid(obj: bpy.types.Object, key: str | None) -> None:
    """Light ``obj`` by the atlas's tile ``key`` (its numbers are written by store_grids), by the file's light
    volume (VOLUME_KEY), or by none (None)."""
    if key is None or key == VOLUME_KEY:
        for name in (GRID_KEY, *GRID_ATTRS.values()):
            obj.pop(name, None)
    obj.pop(VOLUME_ATTR, None)
    if key == VOLUME_KEY:
        obj[VOLUME_ATTR] = 1.0
    if key is not None:
        obj[GRID_KEY] = key
    obj.update_tag()


def has_local_light(obj: bpy.types.Object) -> str | None:
    """"probe" (its own probe), "grid", "volume" or None: what of ours lights ``obj``."""
    key = obj.get(GRID_KEY)
    if not isinstance(key, str):
        return None
    if key == VOLUME_KEY:
        return "volume"
    return "probe" if key.startswith("probe:") else "grid"


def probe_tile(centre, delta: np.ndarray) -> tuple[GridSpec, np.ndarray]:
    """A per-object probe as a tile: a 1 x 1 x 1 grid at ``centre`` holding ``delta`` (9, 3)."""
    c = tuple(float(x) for x in centre)
    return GridSpec(c, c, (1, 1, 1)), np.asarray(delta, np.float32).reshape(1, 1, 1, COEFFS, 3)


def _atlas() -> tuple[bpy.types.Image | None, dict]:
    """Our grid atlas and its tiles {key: {"lo", "hi", "shape", "row0"}}."""
    img = find_ours(bpy.data.images, "grid")
    tiles = json.loads(img.get(TILES, "{}")) if img is not None else {}
    return img, tiles


def _tile_pixels(img: bpy.types.Image, tile: dict) -> np.ndarray:
    """The (nz ny, 9 nx, 3) pixels of one tile of the atlas."""
    nx, ny, nz = tile["shape"]
    return image_pixels(img)[tile["row0"]:tile["row0"] + nz * ny, :COEFFS * nx, :3].copy()


def store_grids(grids: dict[str, tuple[GridSpec, np.ndarray]], world: np.ndarray | None = None,
                irradiance: bpy.types.Image | None = None) -> bpy.types.Image:
    """Put grids {key: (spec, coefficients (nx, ny, nz, 9, 3))} into the file's atlas, replacing tiles of the same
    key and dropping tiles no object points at (call set_object_grid first); then every object lit by a tile gets
    its numbers, and the group is rebuilt for the atlas's size. ``world``: the (9, 3) coefficients of the World
    probe's light the tiles are differences to, and ``irradiance`` its irradiance image (each kept from the last
    call when None; at first a black World and no image)."""
    from ...core.probe.grid import pack_grid
    img, tiles = _atlas()
    used = {o.get(GRID_KEY) for o in bpy.data.objects}
    keep = {k: (t, _tile_pixels(img, t)) for k, t in tiles.items() if k in used and k not in grids}
    for k, (spec, d) in grids.items():
        keep[k] = ({"lo": list(spec.lo), "hi": list(spec.hi), "shape": list(spec.shape)}, pack_grid(d))
    w = max(px.shape[1] for _, px in keep.values())
    h = sum(px.shape[0] for _, px in keep.values())
    atlas = np.zeros((h, w, 3), np.float32)
    row, tiles = 0, {}
    for k, (t, px) in keep.items():
        atlas[row:row + px.shape[0], :px.shape[1]] = px
        tiles[k] = {**t, "row0": row}
        row += px.shape[0]
    old_world = img.get(WORLD_COEFFS) if img is not None else None
    old_irr = img.get(WORLD_IRRADIANCE) if img is not None else None
    img = packed_float_image(atlas, img, "grid", GRID_IMAGE)
    img[TILES] = json.dumps(tiles)
    if world is not None:
        img[WORLD_COEFFS] = json.dumps(np.asarray(world, np.float64).reshape(COEFFS, 3).tolist())
    elif old_world is not None:
        img[WORLD_COEFFS] = old_world
    irr = irradiance if irradiance is not None else old_irr
    if isinstance(irr, bpy.types.Image):
        img[WORLD_IRRADIANCE] = irr
    for o in bpy.data.objects:
        t = tiles.get(o.get(GRID_KEY))
        if t is None:
            continue
        lo, hi, n = np.asarray(t["lo"]), np.asarray(t["hi"]), np.asarray(t["shape"], np.float64)
        o[GRID_ATTRS["lo"]] = [float(c) for c in lo]
        o[GRID_ATTRS["scale"]] = [float(c) for c in (n - 1) / np.where(hi > lo, hi - lo, 1.0)]
        o[GRID_ATTRS["max"]] = [float(c) for c in n - 1]
        o[GRID_ATTRS["tile"]] = [1.0, float(t["row0"]), 0.0]
        o.update_tag()
    local_light_group(img)
    return img


def prune_atlas() -> bool:
    """Drop the grid atlas when no object points at any of its tiles (a file lit by the light volume alone), so the
    group is built without the grid's lookups: Cycles' shader stack holds the grid's or the volume's, not both
    ("out of SVM stack space", the mesh black; blender/lighting/volume_nodes.py). True if it was dropped."""
    img, tiles = _atlas()
    used = {o.get(GRID_KEY) for o in bpy.data.objects}
    if img is None or used & set(tiles):
        return False
    bpy.data.images.remove(img)
    return True


def rebuild_group() -> bpy.types.ShaderNodeTree:
    """The file's local-light group rebuilt for what the file holds now: its grid atlas and its light volume."""
    return local_light_group(_atlas()[0], rebuild=True)


def local_light_group(atlas: bpy.types.Image | None = None, rebuild: bool = False) -> bpy.types.ShaderNodeTree:
    """The file's local-light group; rebuilt to read ``atlas`` (our grid image) when given (and the file's light
    volume, where it has one), or with ``rebuild``."""
    tree = find_ours(bpy.data.node_groups, ROLE)
    if tree is None:
        tree = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
        tree[MARKER] = ROLE
        _interface(tree)
        _build(tree, None)
    elif "EEVEE" not in tree.interface.items_tree:  # a file from before the EEVEE output
        tree.interface.new_socket("EEVEE", in_out="OUTPUT", socket_type="NodeSocketShader")
        _build(tree, None)
    if atlas is not None or rebuild:
        _build(tree, atlas)
    return tree


def _interface(tree) -> None:
    iface = tree.interface
    iface.new_socket("Shader", in_out="INPUT", socket_type="NodeSocketShader")
    albedo_strength_inputs(iface)
    iface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("EEVEE", in_out="OUTPUT", socket_type="NodeSocketShader")


def _world_coefficients(atlas) -> np.ndarray:
    """The (9, 3) World coefficients kept on the atlas (zeros: a black World)."""
    raw = atlas.get(WORLD_COEFFS) if atlas is not None else None
    return np.asarray(json.loads(raw), np.float64) if raw else np.zeros((COEFFS, 3))


def _build(tree, atlas) -> None:
    """(Re)build the group's nodes (core/probe/local_mix.py in nodes): per engine s x shader + Emission(albedo x
    strength x (H - s B)) (Cycles: s x shader + (1 - s) x Diffuse(albedo) + Emission(albedo x strength x (H - B))),
    with w D = w sum_k c_k(P) P_k(n) the mesh's difference. Cycles: H = E + w D over B = E,
    E the World probe's irradiance image along n (what Cycles' diffuse gets from that World; its order-2
    coefficients W where the atlas names no image). EEVEE: H = W + w D over B = EEVEE's order-1 part of W. A mesh
    the light volume lights (VOLUME_ATTR 1) has H = V, the volume's light at its position and normal
    (blender/lighting/volume_nodes.py), in both engines, fading to the World's where it leaves the volume. Without
    an atlas or a volume both outputs pass the shader through. The World's numbers are kept on the atlas, or on the
    volume's image where there is no atlas."""
    from . import volume_nodes
    tree.nodes.clear()
    b = _Nodes(tree)
    N, L = b.N, b.L
    gin, gout = N.new("NodeGroupInput"), N.new("NodeGroupOutput")
    # the volume's lookups only while a mesh reads them: Cycles' shader stack holds the grid's or the volume's, not
    # both (prune_atlas), and a file that went back to grids keeps its volume images for undo
    used = any(o.get(GRID_KEY) == VOLUME_KEY for o in bpy.data.objects)
    volume = {"Shader": volume_nodes.volume_group("CYCLES") if used else None,
              "EEVEE": volume_nodes.volume_group("EEVEE") if used else None}
    world_at = atlas if atlas is not None else volume_nodes.volume_image() if used else None
    if world_at is None:
        L.new(gin.outputs["Shader"], gout.inputs["Shader"])
        L.new(gin.outputs["Shader"], gout.inputs["EEVEE"])
        return
    geo = N.new("ShaderNodeNewGeometry")
    x, y, z = b.separate(geo.outputs["Normal"])
    poly = [None, y, z, x, b.math("MULTIPLY", x, y), b.math("MULTIPLY", y, z),
            b.math("MULTIPLY_ADD", b.math("MULTIPLY", z, z), 3.0, -1.0), b.math("MULTIPLY", x, z),
            b.math("SUBTRACT", b.math("MULTIPLY", x, x), b.math("MULTIPLY", y, y))]

    def poly_sum(coeffs):
        total = None
        for k, c in enumerate(coeffs):
            term = c if poly[k] is None else b.scale(c, poly[k])
            total = term if total is None else b.vec("ADD", total, term)
        return total
    world = _world_coefficients(world_at)
    w_sh = poly_sum([b.const(c) for c in world])
    irr = world_at.get(WORLD_IRRADIANCE)
    if isinstance(irr, bpy.types.Image):
        w_image = latlong_lookup(tree, geo.outputs["Normal"], irr, name="GS-IBL World Irradiance")
    else:
        w_image = w_sh
    here = {"Shader": w_image, "EEVEE": w_sh}
    if atlas is not None:
        coeffs, weight = _grid_lookups(b, geo.outputs["Position"], atlas)
        delta = b.scale(poly_sum(coeffs), weight)
        here = {k: b.vec("ADD", h, delta) for k, h in here.items()}
    if volume["Shader"] is not None:  # H + w (V - H): V where the volume lights the mesh, fading out at its edge
        lit = b.attribute(VOLUME_ATTR, "Fac")
        for k, h in list(here.items()):  # each engine its own group (volume_nodes.py says why)
            vol = N.new("ShaderNodeGroup")
            vol.node_tree = volume[k]
            L.new(geo.outputs["Position"], vol.inputs["Position"])
            L.new(geo.outputs["Normal"], vol.inputs["Normal"])
            w_vol = b.math("MULTIPLY", lit, vol.outputs["Inside"])
            here[k] = b.vec("MULTIPLY_ADD", b.vec("SUBTRACT", vol.outputs["Irradiance"], h),
                            b.combine(w_vol, w_vol, w_vol), h)
    # (H, B) per output: Cycles E + D over E; EEVEE W + D over its order-1 World (core/probe/local_mix.py says why)
    paths = {"Shader": (here["Shader"], w_image),
             "EEVEE": (here["EEVEE"],
                       b.vec("MAXIMUM", poly_sum([b.const(c) for c in eevee_world_order1(world)]), (0.0, 0.0, 0.0)))}
    # the emission is light the engine does not trace: its own mesh's occlusion of it (Only Local AO) stands in
    # for the shadows the user's shader gets from the World (a convex mesh: 1)
    ao = N.new("ShaderNodeAmbientOcclusion")
    ao.only_local, ao.samples = True, AO_SAMPLES
    ao.inputs["Distance"].default_value = AO_DISTANCE
    ao_lit = b.math("POWER", ao.outputs["AO"], AO_LIT_POWER)
    for out_name, (here, base) in paths.items():
        rx, ry, rz = b.separate(b.vec("DIVIDE", here, b.vec("MAXIMUM", base, (EPS, EPS, EPS))))
        s = b.math("MINIMUM", b.math("MINIMUM", rx, ry), rz)
        s.node.use_clamp = True  # 0..1
        # Fac 1 - s: s x the shader, and the rest: in EEVEE nothing (no second shader), in Cycles a diffuse of the
        # albedo, so the World's diffuse light stays traced (shadowed) whole and only the difference H - B is
        # emitted, signed (local_mix.py: the AO stand-in then scales D alone, not the (1 - s) B moved into it)
        mixer = N.new("ShaderNodeMixShader")
        L.new(b.math("SUBTRACT", 1.0, s), mixer.inputs["Fac"])
        L.new(gin.outputs["Shader"], mixer.inputs[1])
        if out_name == "Shader":
            diffuse = N.new("ShaderNodeBsdfDiffuse")
            L.new(gin.outputs["Albedo"], diffuse.inputs["Color"])
            L.new(diffuse.outputs[0], mixer.inputs[2])
            d = b.vec("SUBTRACT", here, base)
            # light the mesh adds (D > 0) is mostly one-directional (a window, a lamp), which the cosine-weighted AO
            # under-shadows: AO^2 (accuracy.md); light it takes away keeps one AO
            rest = b.vec("ADD", b.scale(b.vec("MAXIMUM", d, (0.0, 0.0, 0.0)), ao_lit),
                         b.scale(b.vec("MINIMUM", d, (0.0, 0.0, 0.0)), ao.outputs["AO"]))
        else:
            rest = b.scale(b.vec("SUBTRACT", here, b.scale(base, s)), ao.outputs["AO"])
        lit = b.vec("MULTIPLY", b.scale(rest, gin.outputs["Strength"]), gin.outputs["Albedo"])
        emit = N.new("ShaderNodeEmission")
        L.new(lit, emit.inputs["Color"])
        add = N.new("ShaderNodeAddShader")
        L.new(mixer.outputs[0], add.inputs[0])
        L.new(emit.outputs[0], add.inputs[1])
        L.new(add.outputs[0], gout.inputs[out_name])
    for i, node in enumerate(N):  # a readable layout is not needed to work; a column per creation order will do
        node.location = (200 * (i // 12), -150 * (i % 12))


def _grid_lookups(b: _Nodes, position, atlas) -> tuple[list, object]:
    """(nine vector sockets: the object's grid trilinearly interpolated at ``position``, its weight socket): the
    shader twin of core/probe/grid.py sample_packed, offset to the object's tile of ``atlas``."""
    w, h = atlas.size
    # g = clamp((P - lo) (n - 1) / span, 0, n - 1)
    gmax = b.attribute(GRID_ATTRS["max"])
    g = b.vec("MULTIPLY", b.vec("SUBTRACT", position, b.attribute(GRID_ATTRS["lo"])),
              b.attribute(GRID_ATTRS["scale"]))
    gx, gy, gz = b.separate(b.vec("MINIMUM", b.vec("MAXIMUM", g, (0.0, 0.0, 0.0)), gmax))
    mx, my, mz = b.separate(gmax)
    weight, row0, _ = b.separate(b.attribute(GRID_ATTRS["tile"]))
    nx, ny = b.math("ADD", mx, 1.0), b.math("ADD", my, 1.0)

    def corners(gc, mc):  # the two nodes around a coordinate, and the fraction between them
        c0 = b.math("MINIMUM", b.math("FLOOR", gc), mc)
        return c0, b.math("MINIMUM", b.math("ADD", c0, 1.0), mc), b.math("SUBTRACT", gc, c0)
    x0, x1, fx = corners(gx, mx)
    y0, y1, fy = corners(gy, my)
    z0, z1, fz = corners(gz, mz)
    # texel centres: v = (row0 + z ny + y + 0.5) / h, u = (k nx + x + 0.5) / w
    vs = {(zi, yi): b.math("MULTIPLY_ADD", b.math("ADD", b.math("MULTIPLY_ADD", z, ny, row0), y), 1.0 / h, 0.5 / h)
          for zi, z in enumerate((z0, z1)) for yi, y in enumerate((y0, y1))}

    def lerp(a, c, f):
        return b.vec("MULTIPLY_ADD", b.vec("SUBTRACT", c, a), f, a)
    out = []
    for k in range(COEFFS):
        us = [b.math("MULTIPLY_ADD", b.math("MULTIPLY_ADD", nx, float(k), x), 1.0 / w, 0.5 / w) for x in (x0, x1)]
        texel = {}
        for (zi, yi), v in vs.items():
            for xi, u in enumerate(us):
                uv = b.N.new("ShaderNodeCombineXYZ")
                b.L.new(u, uv.inputs["X"])
                b.L.new(v, uv.inputs["Y"])
                tex = b.N.new("ShaderNodeTexImage")
                tex.image = atlas
                # texel centres read exactly and blended here: EEVEE's Linear filtering blurred a lookup whose
                # coordinates come from object attributes (a coarser level, measured 0.3 -> 0.12)
                tex.interpolation = "Closest"
                tex.extension = "EXTEND"
                b.L.new(uv.outputs[0], tex.inputs["Vector"])
                texel[zi, yi, xi] = tex.outputs["Color"]
        slices = [lerp(lerp(texel[zi, 0, 0], texel[zi, 0, 1], fx), lerp(texel[zi, 1, 0], texel[zi, 1, 1], fx), fy)
                  for zi in (0, 1)]
        out.append(lerp(slices[0], slices[1], fz))
    return out, weight


# ---------------------------------------------------------------------------------------------- materials

def _output(nt):
    outs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    return next((n for n in outs if n.is_active_output), outs[0] if outs else None)


def _our_node(nt):
    return next((n for n in nt.nodes if n.bl_idname == "ShaderNodeGroup" and is_ours(n.node_tree, ROLE)), None)


def in_material(mat: bpy.types.Material | None) -> bool:
    """The material holds our group node."""
    return mat is not None and mat.node_tree is not None and _our_node(mat.node_tree) is not None


def _albedo_input(shader_node):
    """The diffuse colour socket of the user's shader, if it is a shader we know."""
    if shader_node is None:
        return None
    for name in ("Base Color", "Color"):
        if name in shader_node.inputs and shader_node.bl_idname in (
                "ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfOrenNayar"):
            return shader_node.inputs[name]
    return None


def insert_into_material(mat: bpy.types.Material, strength: float = 1.0) -> bool:
    """Put the group between the material's shader and its output (once); True if it was added now.

    The albedo follows the user's Principled/Diffuse colour (linked to the same source, or copied, times
    1 - Metallic when that is a plain number); for other shaders it stays the group's 0.8 grey."""
    nt = node_tree(mat)
    node = _our_node(nt)
    if node is not None:
        node.inputs["Strength"].default_value = strength
        out = _output(nt)
        if out is not None and "EEVEE" in node.outputs and not node.outputs["EEVEE"].links:
            _eevee_output(nt, node, out)  # a material lit before the EEVEE output existed
        return False
    out = _output(nt)
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputMaterial")
    src = out.inputs["Surface"].links[0].from_socket if out.inputs["Surface"].links else None
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = local_light_group()
    node.name = node.label = GROUP_NAME
    node.location = (out.location.x, out.location.y + 220)
    node.inputs["Strength"].default_value = strength
    if src is not None:
        nt.links.new(src, node.inputs["Shader"])
        colour = _albedo_input(src.node)
        if colour is not None:
            if colour.links:
                nt.links.new(colour.links[0].from_socket, node.inputs["Albedo"])
            else:
                rgb = list(colour.default_value)[:3]
                metal = src.node.inputs.get("Metallic")
                keep = 1.0 - float(metal.default_value) if metal is not None and not metal.links else 1.0
                node.inputs["Albedo"].default_value = (*[c * keep for c in rgb], 1.0)
    nt.links.new(node.outputs["EEVEE" if out.target == "EEVEE" else "Shader"], out.inputs["Surface"])
    if out.target == "ALL":
        _eevee_output(nt, node, out)
    return True


def _eevee_output(nt, node, out) -> None:
    """Our Material Output for EEVEE (EEVEE prefers an output of its own target to one for all engines), fed by
    the group's EEVEE output and, for everything else (volume, displacement, thickness), by what feeds ``out``.
    None when the user has an EEVEE output of their own: that one is theirs to keep."""
    if any(n.bl_idname == "ShaderNodeOutputMaterial" and n.target == "EEVEE" for n in nt.nodes):
        return
    ev = nt.nodes.new("ShaderNodeOutputMaterial")
    ev.name = ev.label = EEVEE_OUTPUT
    ev.target = "EEVEE"
    ev.location = (out.location.x, out.location.y - 220)
    nt.links.new(node.outputs["EEVEE"], ev.inputs["Surface"])
    for sock in out.inputs:
        if sock.name != "Surface" and sock.links and sock.name in ev.inputs:
            nt.links.new(sock.links[0].from_socket, ev.inputs[sock.name])


def remove_from_material(mat: bpy.types.Material) -> bool:
    """Take our group node out, linking the user's shader to the output again; True if there was one."""
    nt = mat.node_tree
    node = _our_node(nt) if nt is not None else None
    if node is None:
        return False
    src = node.inputs["Shader"].links[0].from_socket if node.inputs["Shader"].links else None
    targets = [link.to_socket for out in node.outputs for link in out.links
               if link.to_node.name != EEVEE_OUTPUT]
    for n in [n for n in nt.nodes if n.name == EEVEE_OUTPUT and n.bl_idname == "ShaderNodeOutputMaterial"]:
        nt.nodes.remove(n)
    nt.nodes.remove(node)
    if src is not None:
        for sock in targets:
            nt.links.new(src, sock)
    return True


def light_object(obj: bpy.types.Object, strength: float = 1.0) -> None:
    """Every material of ``obj`` gets the group; an object without material gets one of ours (grey diffuse,
    Blender's default look), removed again by unlight_object."""
    if not any(slot.material for slot in obj.material_slots):
        mat = bpy.data.materials.new("GS-IBL Default")
        mat[MARKER] = DEFAULT_MATERIAL_ROLE
        nt = node_tree(mat, clear=True)
        bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
        obj.data.materials.append(mat)
    for slot in obj.material_slots:
        if slot.material is not None and slot.material.library is None:
            insert_into_material(slot.material, strength)


def set_strength(obj: bpy.types.Object, strength: float) -> int:
    """The probe's Strength on the group in ``obj``'s materials (no re-bake); returns how many changed."""
    n = 0
    for slot in obj.material_slots:
        mat = slot.material
        node = _our_node(mat.node_tree) if mat is not None and mat.library is None and mat.node_tree else None
        if node is not None:
            node.inputs["Strength"].default_value = strength
            n += 1
    return n


def unlight_object(obj: bpy.types.Object) -> None:
    """Drop the object's coefficients; take the group out of its materials unless another lit object uses them."""
    set_object_grid(obj, None)
    still_lit = {slot.material for o in bpy.data.objects if o != obj and has_local_light(o)
                 for slot in o.material_slots if slot.material is not None}
    for i in reversed(range(len(obj.material_slots))):
        mat = obj.material_slots[i].material
        if mat is None or mat in still_lit:
            continue
        if is_ours(mat, DEFAULT_MATERIAL_ROLE):
            # the slot goes too (Mesh.materials.pop leaves the object's slot count behind)
            obj.active_material_index = i
            with bpy.context.temp_override(object=obj, active_object=obj, selected_objects=[obj]):
                bpy.ops.object.material_slot_remove()
            if mat.users == 0:
                bpy.data.materials.remove(mat)
            continue
        remove_from_material(mat)
