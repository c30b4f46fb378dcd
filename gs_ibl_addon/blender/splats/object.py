"""Splat objects: the two kinds a probe bakes from, read by one function (``scene_from_object``).

* Ours: a mesh of loose vertices that carries every splat, saved inside the .blend (below).
* Blender 5.3+'s native splats: a Point Cloud with ``type == 'GAUSSIAN_SPLAT'`` (made by Blender's PLY, SPZ and glTF
  importers, and by ours on 5.3+ unless asked for a mesh), whose point attributes are ``radiance:base`` (FLOAT4:
  f_dc RGB as stored, then opacity after the sigmoid), ``scale`` (after exp), ``rotation`` (QUATERNION, w x y z)
  and ``radiance:sh_0`` .. ``radiance:sh_14`` (one RGB per higher SH coefficient, 3DGS order). Read with
  foreach_get straight into numpy.
Either kind carries a colour space (Object.gs_ibl_splats.colour_space, core/colour.py): our mesh takes the file's
declaration at import; a native one defaults to sRGB, Blender's own rule, and ours stores a linear file's colours
re-encoded for that rule (_fill_pointcloud), so Blender's renders and our bakes read them alike.

Our mesh:

One vertex per splat (its position); the other activated SplatScene fields are point-domain attributes:
  gs_scale (FLOAT_VECTOR), gs_rotation (QUATERNION, w x y z), gs_opacity (FLOAT), gs_sh_00 .. gs_sh_NN
  (FLOAT_VECTOR, one per SH coefficient, RGB) and gs_color (FLOAT_COLOR: the DC colour + opacity, for display).
The object's matrix_world is the splats' transform (import axis conversion included), so moving the object
moves the light. Deleting vertices in Edit Mode crops the splats: every attribute stays per vertex.

Loose vertices are not drawn in Object Mode, so a Geometry Nodes modifier shows a random subset of them as
points (at most PROXY_POINTS) with their colour; very large scenes also switch to bounds display. The modifier also
puts out two points of radius 0 at the corners of every splat's bounds: Blender frames (View Selected, Numpad .)
and culls the evaluated geometry, which with the subset alone, or with none while the overlay shows (Fraction 0),
was a part of the capture or nothing at all (View Selected then framed the object's origin: a person's legs).
Its camera icon (hide_render) is on after an import, like any object's: F12 draws it with our renderer
(blender/render/); the point proxy is a viewport stand-in that never renders (its modifier's show_render is off).
"""
from __future__ import annotations

from typing import Generator

import bpy
import numpy as np
from bpy.app.handlers import persistent
from mathutils import Matrix

from ...core.colour import linear_sh_for_srgb_rule
from ...core.scene import SplatScene, combine_scenes, sh_dc_to_rgb
from ...core.sh import degree_of
from ..common import handlers
from ..common.compat import modifier_input_identifiers, node_output, node_tree, set_modifier_input
from ..common.datablocks import MARKER, find_ours
from ..common.jobs import Step, run_now

# The splat object's MARKER is a dict {"source": path, "sh_degree": d, "version": 1}; the proxy's material and
# node tree carry these roles (found by them, never by name: datablocks.py).
PROXY_TREE_ROLE = "proxy_tree"
PROXY_MATERIAL_ROLE = "proxy_material"
PROXY_TREE = "GS-IBL Splat Proxy"
PROXY_MATERIAL = "GS-IBL Splat Colour"
PROXY_MODIFIER = "GS-IBL Proxy"
PROXY_POINTS = 200_000  # points drawn at most; the data keeps every splat
BOUNDS_ABOVE = 5_000_000  # above this many splats the object shows as its bounds box

_SH_NAME = "gs_sh_{:02d}"


def is_mesh_splats(obj: bpy.types.Object | None) -> bool:
    """One of ours: a mesh made by our importer."""
    return obj is not None and obj.type == "MESH" and MARKER in obj.keys()


def is_native_splats(obj: bpy.types.Object | None) -> bool:
    """A Blender 5.3+ Gaussian-splat Point Cloud (Blender draws and renders it itself)."""
    return obj is not None and obj.type == "POINTCLOUD" and getattr(obj.data, "type", None) == "GAUSSIAN_SPLAT"


def is_splat_object(obj: bpy.types.Object | None) -> bool:
    """Either kind of splat object: what a probe can bake from."""
    return is_mesh_splats(obj) or is_native_splats(obj)


def in_view_layer(obj: bpy.types.Object, layer: bpy.types.ViewLayer) -> bool:
    """Whether ``obj`` is in ``layer`` (not in a collection the layer excludes): what a render of that layer holds."""
    try:
        return obj.name in layer.objects
    except (AttributeError, ReferenceError):
        return True


def current_layer(scene: bpy.types.Scene) -> bpy.types.ViewLayer:
    """The view layer the user works in for ``scene`` (the window's), else the scene's first."""
    layer = getattr(bpy.context, "view_layer", None)
    if layer is not None and getattr(bpy.context, "scene", None) == scene:
        return layer
    return scene.view_layers[0]


def splat_count(obj: bpy.types.Object) -> int:
    return len(obj.data.points) if is_native_splats(obj) else len(obj.data.vertices)


def colour_space_of(obj: bpy.types.Object) -> str:
    """The object's colour space, as the core names it ("srgb" or "linear")."""
    settings = getattr(obj, "gs_ibl_splats", None)
    return settings.colour_space.lower() if settings is not None else "srgb"


def _new_attr(mesh: bpy.types.Mesh, name: str, kind: str, field: str, values: np.ndarray) -> None:
    attr = mesh.attributes.new(name, kind, "POINT")
    attr.data.foreach_set(field, np.ascontiguousarray(values, np.float32).ravel())


def _filled(name: str, i: int, total: int) -> Step:
    return Step(f"making {name}: {i} of {total} attributes")


def _fill_mesh(mesh: bpy.types.Mesh, scene: SplatScene) -> Generator[Step, None, None]:
    """Our mesh's vertices and attributes from ``scene``, an attribute at a time (a Runner lets the window draw
    between them: at 3M splats each is ~0.1 s)."""
    n = scene.count
    total = 5 + scene.sh.shape[1]
    mesh.vertices.add(n)
    mesh.attributes["position"].data.foreach_set("vector", np.ascontiguousarray(scene.positions, np.float32).ravel())
    yield _filled(mesh.name, 1, total)
    _new_attr(mesh, "gs_scale", "FLOAT_VECTOR", "vector", scene.scales)
    _new_attr(mesh, "gs_rotation", "QUATERNION", "value", scene.rotations)
    _new_attr(mesh, "gs_opacity", "FLOAT", "value", scene.opacities)
    yield _filled(mesh.name, 4, total)
    for k in range(scene.sh.shape[1]):
        _new_attr(mesh, _SH_NAME.format(k), "FLOAT_VECTOR", "vector", scene.sh[:, k])
        yield _filled(mesh.name, 5 + k, total)
    rgba = np.empty((n, 4), np.float32)
    rgba[:, :3] = np.maximum(sh_dc_to_rgb(scene.sh[:, 0]), 0.0)
    rgba[:, 3] = scene.opacities
    _new_attr(mesh, "gs_color", "FLOAT_COLOR", "color", rgba)
    mesh.color_attributes.active_color = mesh.color_attributes["gs_color"]
    mesh.update()


def _proxy_material() -> bpy.types.Material:
    mat = find_ours(bpy.data.materials, PROXY_MATERIAL_ROLE)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(PROXY_MATERIAL)
    mat[MARKER] = PROXY_MATERIAL_ROLE
    nt = node_tree(mat, clear=True)
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "gs_color"
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(attr.outputs["Color"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def _proxy_tree() -> bpy.types.NodeTree:
    """Geometry Nodes: a random fraction of the vertices as coloured points (display only)."""
    tree = find_ours(bpy.data.node_groups, PROXY_TREE_ROLE)
    if tree is not None:
        add_proxy_bounds(tree)  # one a file saved before the bounds points
        return tree
    tree = bpy.data.node_groups.new(PROXY_TREE, "GeometryNodeTree")
    tree[MARKER] = PROXY_TREE_ROLE
    iface = tree.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    frac = iface.new_socket("Fraction", in_out="INPUT", socket_type="NodeSocketFloat")
    frac.default_value, frac.min_value, frac.max_value = 1.0, 0.0, 1.0
    rad = iface.new_socket("Radius", in_out="INPUT", socket_type="NodeSocketFloat")
    rad.default_value, rad.min_value = 0.01, 0.0
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n = tree.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    rnd = n.new("FunctionNodeRandomValue")
    rnd.data_type = "BOOLEAN"
    pts = n.new("GeometryNodeMeshToPoints")
    setmat = n.new("GeometryNodeSetMaterial")
    setmat.inputs["Material"].default_value = _proxy_material()
    L = tree.links
    L.new(gin.outputs["Fraction"], rnd.inputs["Probability"])
    L.new(gin.outputs["Geometry"], pts.inputs["Mesh"])
    L.new(node_output(rnd, "BOOLEAN"), pts.inputs["Selection"])
    L.new(gin.outputs["Radius"], pts.inputs["Radius"])
    L.new(pts.outputs["Points"], setmat.inputs["Geometry"])
    L.new(setmat.outputs["Geometry"], gout.inputs[0])
    add_proxy_bounds(tree)
    return tree


BOUNDS_NODE = "GS-IBL Splat Bounds"  # the proxy tree's Bounding Box node (its presence: the tree is up to date)


def add_proxy_bounds(tree: bpy.types.NodeTree) -> bool:
    """Two points of radius 0 (nothing drawn) at the min and max corners of the input's bounds, joined to the
    tree's output, so the evaluated object's bounds hold every splat whatever the Fraction. A proxy tree made
    before they existed (a saved .blend) gets them here; True if added now."""
    n = tree.nodes
    if n.get(BOUNDS_NODE) is not None:
        return False
    gin = next((x for x in n if x.bl_idname == "NodeGroupInput"), None)
    gout = next((x for x in n if x.bl_idname == "NodeGroupOutput"), None)
    if gin is None or gout is None or not gout.inputs[0].links:
        return False  # not the tree this module made: left alone
    shown = gout.inputs[0].links[0].from_socket
    box = n.new("GeometryNodeBoundBox")
    box.name = box.label = BOUNDS_NODE
    join = n.new("GeometryNodeJoinGeometry")
    L = tree.links
    L.new(gin.outputs["Geometry"], box.inputs["Geometry"])
    L.new(shown, join.inputs["Geometry"])
    for corner in ("Min", "Max"):
        point = n.new("GeometryNodePoints")
        point.inputs["Count"].default_value = 1
        point.inputs["Radius"].default_value = 0.0
        L.new(box.outputs[corner], point.inputs["Position"])
        L.new(point.outputs["Points"], join.inputs["Geometry"])
    L.new(join.outputs["Geometry"], gout.inputs[0])
    return True


def upgrade_proxy_trees() -> int:
    """Give every proxy tree of the open file its bounds points (add_proxy_bounds); returns how many changed."""
    return sum(add_proxy_bounds(t) for t in bpy.data.node_groups
               if t.get(MARKER) == PROXY_TREE_ROLE and t.library is None)


@persistent
def on_load_post(*_args) -> None:
    upgrade_proxy_trees()  # a file saved before the bounds points frames its splats whole too


_HANDLERS = (("load_post", on_load_post),)


def register_handlers() -> None:
    handlers.add(_HANDLERS)


def unregister_handlers() -> None:
    handlers.remove(_HANDLERS)


def _add_proxy(obj: bpy.types.Object, scene: SplatScene) -> None:
    tree = _proxy_tree()
    mod = obj.modifiers.new(PROXY_MODIFIER, "NODES")
    mod.show_render = False  # the splats themselves are drawn in renders (blender/render/), never these points
    mod.node_group = tree
    ids = modifier_input_identifiers(tree)
    set_modifier_input(mod, ids["Fraction"], float(min(1.0, PROXY_POINTS / max(scene.count, 1))))
    radius = float(np.median(scene.scales.mean(1))) if scene.count else 0.01
    set_modifier_input(mod, ids["Radius"], max(radius, 1e-4))
    if scene.count > BOUNDS_ABOVE:
        obj.display_type = "BOUNDS"


def native_splats_supported() -> bool:
    """Blender 5.3+: a Point Cloud can be Gaussian splats, which Blender draws and renders itself."""
    cloud_type = getattr(bpy.types, "PointCloud", None)
    prop = cloud_type.bl_rna.properties.get("type") if cloud_type is not None else None
    return prop is not None and "GAUSSIAN_SPLAT" in prop.enum_items.keys()


def _fill_pointcloud(cloud, scene: SplatScene) -> Generator[Step, None, str]:
    """Blender's own splat attributes from ``scene``; returns the colour space the stored colours are in.

    Blender reads every splat's colour as sRGB (radiance = srgb_to_linear(SH + 0.5)). A linear scene is stored
    re-encoded (core/colour.py linear_sh_for_srgb_rule: the DC colour exact, view dependence to first order), so that
    Blender's renders show the radiance the file meant, and the object's colour space is then sRGB: our bake reads
    the stored colours as Blender does. An attribute at a time, as _fill_mesh."""
    n = scene.count
    total = 3 + scene.sh.shape[1]
    cloud.type = "GAUSSIAN_SPLAT"
    cloud.resize(n)
    cloud.attributes["position"].data.foreach_set("vector", np.ascontiguousarray(scene.positions, np.float32).ravel())
    sh = scene.sh if scene.colour_space == "srgb" else linear_sh_for_srgb_rule(scene.sh)
    base = np.empty((n, 4), np.float32)
    base[:, :3] = sh[:, 0]
    base[:, 3] = scene.opacities
    _new_attr(cloud, "radiance:base", "FLOAT4", "vector", base)
    yield _filled(cloud.name, 2, total)
    _new_attr(cloud, "scale", "FLOAT_VECTOR", "vector", scene.scales)
    _new_attr(cloud, "rotation", "QUATERNION", "value", scene.rotations)
    yield _filled(cloud.name, 4, total)
    for k, plane in enumerate(_sh_planes(sh), 1):
        _new_attr(cloud, _NATIVE_SH.format(k - 1), "FLOAT_VECTOR", "vector", plane)
        yield _filled(cloud.name, 4 + k, total)
    return "srgb"


def _sh_planes(sh: np.ndarray, step: int = 1 << 13) -> np.ndarray:
    """The higher SH coefficients as (k - 1, n, 3) contiguous planes, one per attribute. Copied a block of splats at
    a time: a strided copy of each coefficient over the whole (n, k, 3) array reads all of it once per coefficient
    (15 times at degree 3), a block stays in the CPU's cache for all of them."""
    n, k = sh.shape[:2]
    out = np.empty((k - 1, n, 3), np.float32)
    for i in range(0, n, step):
        out[:, i:i + step] = sh[i:i + step, 1:].transpose(1, 0, 2)
    return out


def create_splat_object(context: bpy.types.Context, scene: SplatScene, name: str,
                        matrix: np.ndarray | None = None, proxy: bool = True,
                        native: bool = False) -> bpy.types.Object:
    """A new splat object holding ``scene``, linked to the active collection, selected and active (create_steps
    run now)."""
    return run_now(create_steps(context, scene, name, matrix, proxy, native))


def create_steps(context: bpy.types.Context, scene: SplatScene, name: str, matrix: np.ndarray | None = None,
                 proxy: bool = True, native: bool = False) -> Generator[Step, None, bpy.types.Object]:
    """create_splat_object as a job (blender/jobs.py), an attribute at a time.

    native=True (Blender 5.3+, native_splats_supported()): a Gaussian-splat Point Cloud that Blender draws and
    renders itself (viewport, EEVEE, Cycles), with no proxy or overlay of ours; otherwise our mesh of loose vertices
    (never rendered: its light reaches meshes through a baked probe) with a point proxy if ``proxy``.
    On any failure, and when the job is cancelled between two attributes, every datablock made here is removed
    again, so the file is as it was. The datablocks belong to no object until the last step: nothing draws them.
    """
    if native and not native_splats_supported():
        raise ValueError(f"Blender {bpy.app.version_string} has no native Gaussian splats (5.3 and later do): "
                         "import as a mesh with the GS-IBL overlay")
    data = bpy.data.pointclouds.new(name) if native else bpy.data.meshes.new(name)
    obj = None
    try:
        if native:
            space = yield from _fill_pointcloud(data, scene)
        else:
            yield from _fill_mesh(data, scene)
            space = scene.colour_space
        collection = context.collection
        obj = bpy.data.objects.new(name, data)
        obj[MARKER] = {"source": scene.source, "sh_degree": scene.sh_degree, "version": 1,
                       "declared_colour_space": scene.colour_space}
        if hasattr(obj, "gs_ibl_splats"):  # registered (not in a bare bpy that only builds objects)
            obj.gs_ibl_splats.colour_space = space.upper()  # the file's declaration (else sRGB), as stored
        if matrix is not None:
            # a Matrix, not nested lists: RNA would read nested lists column-major (transposed)
            obj.matrix_world = Matrix([list(r) for r in np.asarray(matrix, np.float64)])
        if not native:
            if proxy:
                _add_proxy(obj, scene)
        collection.objects.link(obj)
    except BaseException:  # GeneratorExit too: a cancelled import leaves nothing behind
        if obj is not None:
            bpy.data.objects.remove(obj)
        (bpy.data.pointclouds if native else bpy.data.meshes).remove(data)
        raise
    for o in context.view_layer.objects.selected:
        o.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


# Attribute data type -> foreach_get key and floats per element (Blender 5.3's FLOAT4 reads as "vector").
_FIELDS = {"FLOAT": ("value", 1), "FLOAT_VECTOR": ("vector", 3), "QUATERNION": ("value", 4),
           "FLOAT_COLOR": ("color", 4), "FLOAT4": ("vector", 4), "FLOAT2": ("vector", 2)}


def _read_attr(geometry, name: str, n: int, width: int, out: np.ndarray | None = None) -> np.ndarray:
    """Attribute ``name`` of ``n`` points as (n, width) float32 (n,) for width 1, without a Python list; into
    ``out`` (C-contiguous float32 of that size) when given."""
    attr = geometry.attributes.get(name)
    if attr is None:
        raise ValueError(f"splat object {geometry.name!r} lacks attribute {name!r}: re-import the splat file")
    key, w = _FIELDS.get(attr.data_type, (None, 0))
    if w != width:
        raise ValueError(f"splat object {geometry.name!r}: attribute {name!r} is {attr.data_type}, expected "
                         f"{width} floats per point: re-import the splat file")
    flat = np.empty(n * width, np.float32) if out is None else out.reshape(-1)
    attr.data.foreach_get(key, flat)
    return flat.reshape((n, width)) if width > 1 else flat


def _mesh_steps(mesh: bpy.types.Mesh, source: str) -> Generator[Step, None, SplatScene]:
    """The splats as stored, in the object's local space, an attribute at a time (a Runner lets the window draw
    between them: 3M splats read in ~20 pieces of ~0.15 s)."""
    n = len(mesh.vertices)
    k = 0
    while mesh.attributes.get(_SH_NAME.format(k)) is not None:
        k += 1
    if k not in (1, 4, 9, 16):
        raise ValueError(f"splat object {mesh.name!r} has {k} SH attributes (expected 1, 4, 9 or 16): re-import it")
    fields = [("position", 3), ("gs_scale", 3), ("gs_rotation", 4), ("gs_opacity", 1)]
    total = len(fields) + k
    read = {}
    for i, (name, width) in enumerate(fields):
        read[name] = _read_attr(mesh, name, n, width)
        yield Step(f"reading {n:,} splats of {mesh.name!r} ({i + 1}/{total})")
    # Each SH attribute straight into its own plane: no stacking copy here on the main thread (0.5 s at 1M); the
    # scene's sh is a (N, K, 3) view of the planes, made contiguous by whoever needs it (to_world, on a worker).
    planes = np.empty((k, n, 3), np.float32)
    for i in range(k):
        _read_attr(mesh, _SH_NAME.format(i), n, 3, out=planes[i])
        yield Step(f"reading {n:,} splats of {mesh.name!r} ({len(fields) + i + 1}/{total})")
    return SplatScene(read["position"], read["gs_scale"], read["gs_rotation"], read["gs_opacity"],
                      planes.transpose(1, 0, 2), source=source)


def scene_from_mesh(mesh: bpy.types.Mesh, source: str = "<blender>") -> SplatScene:
    """The splats as stored, in the object's local space."""
    return run_now(_mesh_steps(mesh, source))


_NATIVE_SH = "radiance:sh_{}"


def _pointcloud_steps(cloud, source: str) -> Generator[Step, None, SplatScene]:
    """A native Gaussian-splat Point Cloud's splats as Blender stores them, in the object's local space, an
    attribute at a time (as _mesh_steps)."""
    n = len(cloud.points)
    rest = 0
    while cloud.attributes.get(_NATIVE_SH.format(rest)) is not None:
        rest += 1
    try:
        degree_of(rest + 1)
    except ValueError:
        raise ValueError(f"splat object {cloud.name!r} has {rest} radiance:sh_* attributes (expected 0, 3, 8 or "
                         "15): re-import it") from None
    total = 4 + rest

    def done(i: int) -> Step:
        return Step(f"reading {n:,} splats of {cloud.name!r} ({i}/{total})")

    base = _read_attr(cloud, "radiance:base", n, 4)
    yield done(1)
    sh = np.empty((n, rest + 1, 3), np.float32)
    sh[:, 0] = base[:, :3]
    for k in range(rest):
        sh[:, k + 1] = _read_attr(cloud, _NATIVE_SH.format(k), n, 3)
        yield done(2 + k)
    pos = _read_attr(cloud, "position", n, 3)
    scales = _read_attr(cloud, "scale", n, 3)
    yield done(total - 1)
    rotations = _read_attr(cloud, "rotation", n, 4)
    yield done(total)
    return SplatScene(pos, scales, rotations, np.ascontiguousarray(base[:, 3]), sh, source=source)


def scene_from_pointcloud(cloud, source: str = "<blender>") -> SplatScene:
    """A native Gaussian-splat Point Cloud's splats as Blender stores them, in the object's local space."""
    return run_now(_pointcloud_steps(cloud, source))


def read_steps(obj: bpy.types.Object) -> Generator[Step, None, tuple[SplatScene, np.ndarray]]:
    """(the object's splats in its local space, with its colour space, and its matrix_world): the main thread's part
    of reading a splat object, a piece at a time; to_world() (any thread) finishes it."""
    if is_native_splats(obj):
        info = obj.get(MARKER)  # one of ours remembers its file; Blender's own importers' know none
        local = yield from _pointcloud_steps(obj.data, str(info.get("source", obj.name)) if hasattr(info, "get")
                                             else obj.name)
    elif is_mesh_splats(obj):
        info = obj[MARKER]
        local = yield from _mesh_steps(obj.data, str(info.get("source", obj.name)) if hasattr(info, "get")
                                       else obj.name)
    else:
        raise ValueError(f"{obj.name if obj else None!r} is not a splat object (import a splat file first, or pick "
                         "a Gaussian-splat Point Cloud)")
    local.colour_space = colour_space_of(obj)
    return local, np.array(obj.matrix_world, np.float64)


def to_world(local: SplatScene, matrix: np.ndarray, name: str) -> SplatScene:
    """``local`` moved by the object's ``matrix`` into Blender world space: view-dependent colour (SH degree >= 1)
    turns with the object, as Blender's own splats do (it evaluates them in the object's frame). No bpy: a worker
    thread runs it for 3M splats (seconds of SH rotation).

    Raises ValueError naming the object when its transform cannot move splats (non-uniform or mirrored scale).
    """
    if not local.sh.flags.c_contiguous:  # read_steps hands over the SH as a view of per-coefficient planes
        local.sh = np.ascontiguousarray(local.sh)
    try:
        return local.transformed(matrix)
    except ValueError as e:
        # The core's message says what is wrong with the matrix; the user needs to know which object has it.
        raise ValueError(f"{name}: {e}") from e


def merged_world(parts: list[tuple[SplatScene, np.ndarray, str]]) -> SplatScene:
    """Several objects' splats (read_steps' (local, matrix) and the object's name, each) in world space as one
    scene, sorted together by whatever renders it: the light of a probe that several captures surround
    (core.scene.combine_scenes: a mix of colour spaces drawn by Blender's rule, as F12 draws them)."""
    if len(parts) == 1:
        return to_world(*parts[0])
    return combine_scenes([to_world(*x) for x in parts], "+".join(x[2] for x in parts))


def scene_from_object(obj: bpy.types.Object) -> SplatScene:
    """Either kind of splat object's splats in Blender world space (its matrix_world applied), with its colour
    space: what a probe bake needs (read_steps, then to_world)."""
    local, matrix = run_now(read_steps(obj))
    return to_world(local, matrix, obj.name)
