"""The material node group through which a mesh gets light of its own: a per-object probe or the probe grid.

The World (one probe) keeps lighting every mesh: background, specular and diffuse. A mesh whose light differs
from the World probe's gets the difference added to its material's surface shader:

    surface = the user's shader + Emission(albedo x strength x (E_here(n) - E_world(n)))

so its diffuse part sees E_here (its own probe, or the grid at the shading point) and everything else of the
user's material stays as it was. E is order-2 SH irradiance, kept as the nine monomial coefficients of
core/probe/grid.py, so the group is a sum of nine colours times polynomials of the world normal:
- per object: the object's custom properties ``gs_ibl_sh_0 .. gs_ibl_sh_8`` (E_here - E_world at its centre),
  read by Attribute nodes of type Object (0 when absent: objects sharing the material without a probe of
  their own keep the World's light);
- the grid: the grid image of core/probe/grid.py (``pack_grid``), two bilinear lookups per coefficient blended
  across z, weighted by the object's custom property ``gs_ibl_grid`` (1 for meshes lit by the grid).

One group per file (like the irradiance group); inserting it into a material puts one group node between the
user's shader and the Material Output; ``remove_from_material`` links them directly again and deletes only our
node, so nothing of the user's material is lost. The state lives in datablocks (custom properties, a packed
image, the group), so it follows undo and save/reload.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.probe.grid import COEFFS, GridSpec
from .compat import node_tree
from .datablocks import MARKER, find_ours, is_ours

GROUP_NAME = "GS-IBL Local Light"
ROLE = "local_light"
SH_PROP = "gs_ibl_sh_{}"  # object custom property: coefficient k of E_here - E_world (RGB)
GRID_PROP = "gs_ibl_grid"  # object custom property: 1.0 where the grid lights the object
GRID_IMAGE = "GS-IBL Grid"
DEFAULT_MATERIAL_ROLE = "local_material"


def set_object_coefficients(obj: bpy.types.Object, delta: np.ndarray | None, grid: bool) -> None:
    """Per-object coefficients (9, 3) of E_here - E_world, or None to drop them; ``grid``: lit by the grid."""
    for k in range(COEFFS):
        if delta is None:
            obj.pop(SH_PROP.format(k), None)
        else:
            obj[SH_PROP.format(k)] = [float(c) for c in delta[k]]
    if grid:
        obj[GRID_PROP] = 1.0
    else:
        obj.pop(GRID_PROP, None)


def has_local_light(obj: bpy.types.Object) -> str | None:
    """"probe", "grid" or None: what of ours lights ``obj``."""
    if SH_PROP.format(0) in obj.keys():
        return "probe"
    return "grid" if GRID_PROP in obj.keys() else None


def grid_image(pixels: np.ndarray, image: bpy.types.Image | None = None) -> bpy.types.Image:
    """Our packed float image holding the grid (H, W, 3; row 0 at the bottom), updated in place when it is ours."""
    px = np.asarray(pixels, np.float32)
    h, w = px.shape[:2]
    img = image if is_ours(image, "grid") else find_ours(bpy.data.images, "grid")
    if img is not None and (tuple(img.size) != (w, h) or not img.is_float):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(GRID_IMAGE, w, h, alpha=False, float_buffer=True)
        img[MARKER] = "grid"
        # data, not colour: no view transform may touch the coefficients (set before the pixels: setting the
        # colour space afterwards empties the buffer, blender/world.py _save_exr)
        img.colorspace_settings.is_data = True
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = px
    img.pixels.foreach_set(rgba.ravel())
    img.file_format = "OPEN_EXR"  # packed as float: the coefficients are signed
    img.pack()
    img.update()
    return img


def local_light_group(grid: GridSpec | None = None, image: bpy.types.Image | None = None) -> bpy.types.ShaderNodeTree:
    """The file's local-light group, (re)built for ``grid`` (None: keep the grid it has, if any)."""
    tree = find_ours(bpy.data.node_groups, ROLE)
    if tree is None:
        tree = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
        tree[MARKER] = ROLE
        _interface(tree)
        _build(tree, None, None)
    if grid is not None:
        _build(tree, grid, image)
    return tree


def _interface(tree) -> None:
    iface = tree.interface
    iface.new_socket("Shader", in_out="INPUT", socket_type="NodeSocketShader")
    alb = iface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    alb.default_value = (0.8, 0.8, 0.8, 1.0)
    st = iface.new_socket("Strength", in_out="INPUT", socket_type="NodeSocketFloat")
    st.default_value, st.min_value = 1.0, 0.0
    iface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")


class _Nodes:
    """Small helpers that add math nodes to a tree, each returning the output socket."""

    def __init__(self, tree):
        self.tree, self.N, self.L = tree, tree.nodes, tree.links

    def _set(self, node, inputs):
        for i, v in enumerate(inputs):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                node.inputs[i].default_value = v
            elif isinstance(v, tuple):
                node.inputs[i].default_value = v
            else:
                self.L.new(v, node.inputs[i])
        return node.outputs[0]

    def math(self, op, *inputs):
        m = self.N.new("ShaderNodeMath")
        m.operation = op
        return self._set(m, inputs)

    def vec(self, op, *inputs):
        m = self.N.new("ShaderNodeVectorMath")
        m.operation = op
        out = self._set(m, inputs)
        return m.outputs["Vector"] if op != "DOT_PRODUCT" else out

    def scale(self, v, s):
        m = self.N.new("ShaderNodeVectorMath")
        m.operation = "SCALE"
        self._set(m, (v,))
        self.L.new(s, m.inputs["Scale"]) if not isinstance(s, (int, float)) else \
            setattr(m.inputs["Scale"], "default_value", s)
        return m.outputs["Vector"]


def _build(tree, grid: GridSpec | None, image) -> None:
    """(Re)build the group's nodes: sum_k (attr_k + w_grid grid_k(P)) P_k(n), emitted times albedo x strength."""
    tree.nodes.clear()
    b = _Nodes(tree)
    N, L = b.N, b.L
    gin, gout = N.new("NodeGroupInput"), N.new("NodeGroupOutput")
    geo = N.new("ShaderNodeNewGeometry")
    n = N.new("ShaderNodeSeparateXYZ")
    L.new(geo.outputs["Normal"], n.inputs[0])
    x, y, z = n.outputs["X"], n.outputs["Y"], n.outputs["Z"]
    poly = [None, y, z, x, b.math("MULTIPLY", x, y), b.math("MULTIPLY", y, z),
            b.math("MULTIPLY_ADD", b.math("MULTIPLY", z, z), 3.0, -1.0), b.math("MULTIPLY", x, z),
            b.math("SUBTRACT", b.math("MULTIPLY", x, x), b.math("MULTIPLY", y, y))]
    grid_terms = _grid_lookups(b, geo.outputs["Position"], grid, image) if grid is not None else None
    weight = None
    if grid_terms is not None:
        wattr = N.new("ShaderNodeAttribute")
        wattr.attribute_type, wattr.attribute_name = "OBJECT", GRID_PROP
        weight = wattr.outputs["Fac"]
    total = None
    for k in range(COEFFS):
        attr = N.new("ShaderNodeAttribute")
        attr.attribute_type, attr.attribute_name = "OBJECT", SH_PROP.format(k)
        attr.name = attr.label = f"GS-IBL SH {k}"
        c = attr.outputs["Vector"]
        if grid_terms is not None:
            c = b.vec("MULTIPLY_ADD", grid_terms[k], weight, c)
        term = c if poly[k] is None else b.scale(c, poly[k])
        total = term if total is None else b.vec("ADD", total, term)
    lit = b.vec("MULTIPLY", b.scale(total, gin.outputs["Strength"]), gin.outputs["Albedo"])
    emit = N.new("ShaderNodeEmission")
    L.new(lit, emit.inputs["Color"])
    add = N.new("ShaderNodeAddShader")
    L.new(gin.outputs["Shader"], add.inputs[0])
    L.new(emit.outputs[0], add.inputs[1])
    L.new(add.outputs[0], gout.inputs["Shader"])
    for i, node in enumerate(N):  # a readable layout is not needed to work; a column per creation order will do
        node.location = (200 * (i // 12), -150 * (i % 12))


def _grid_lookups(b: _Nodes, position, grid: GridSpec, image) -> list:
    """Nine vector sockets: the grid's coefficients trilinearly interpolated at ``position`` (the shader twin of
    core/probe/grid.py sample_packed)."""
    nx, ny, nz = grid.shape
    lo, hi = np.asarray(grid.lo), np.asarray(grid.hi)
    span = np.where(hi > lo, hi - lo, 1.0)
    w, h = COEFFS * nx, nz * ny
    # g = clamp((P - lo) (n - 1) / span, 0, n - 1)
    g = b.vec("MULTIPLY", b.vec("SUBTRACT", position, tuple(float(c) for c in lo)),
              tuple(float(c) for c in (np.asarray(grid.shape) - 1) / span))
    g = b.vec("MINIMUM", b.vec("MAXIMUM", g, (0.0, 0.0, 0.0)), tuple(float(c - 1) for c in grid.shape))
    sep = b.N.new("ShaderNodeSeparateXYZ")
    b.L.new(g, sep.inputs[0])
    gx, gy, gz = sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]
    z0 = b.math("MINIMUM", b.math("FLOOR", gz), float(nz - 1))
    z1 = b.math("MINIMUM", b.math("ADD", z0, 1.0), float(nz - 1))
    fz = b.math("SUBTRACT", gz, z0)
    # v of the two slices: (z ny + gy + 0.5) / h
    v0 = b.math("MULTIPLY_ADD", gy, 1.0 / h, b.math("MULTIPLY_ADD", z0, ny / h, 0.5 / h))
    v1 = b.math("MULTIPLY_ADD", gy, 1.0 / h, b.math("MULTIPLY_ADD", z1, ny / h, 0.5 / h))
    out = []
    for k in range(COEFFS):
        u = b.math("MULTIPLY_ADD", gx, 1.0 / w, (k * nx + 0.5) / w)
        slices = []
        for v in (v0, v1):
            uv = b.N.new("ShaderNodeCombineXYZ")
            b.L.new(u, uv.inputs["X"])
            b.L.new(v, uv.inputs["Y"])
            tex = b.N.new("ShaderNodeTexImage")
            tex.image = image
            tex.interpolation = "Linear"
            tex.extension = "EXTEND"
            b.L.new(uv.outputs[0], tex.inputs["Vector"])
            slices.append(tex.outputs["Color"])
        lower, upper = slices
        out.append(b.vec("MULTIPLY_ADD", b.vec("SUBTRACT", upper, lower), fz, lower))
    return out


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
    nt.links.new(node.outputs["Shader"], out.inputs["Surface"])
    return True


def remove_from_material(mat: bpy.types.Material) -> bool:
    """Take our group node out, linking the user's shader to the output again; True if there was one."""
    nt = mat.node_tree
    node = _our_node(nt) if nt is not None else None
    if node is None:
        return False
    src = node.inputs["Shader"].links[0].from_socket if node.inputs["Shader"].links else None
    targets = [link.to_socket for link in node.outputs["Shader"].links]
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


def unlight_object(obj: bpy.types.Object) -> None:
    """Drop the object's coefficients; take the group out of its materials unless another lit object uses them."""
    set_object_coefficients(obj, None, grid=False)
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
