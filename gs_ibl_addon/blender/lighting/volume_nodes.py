"""The light volume's node group: core/probe/volume.py ``sample_packed`` in shader nodes, for EEVEE and Cycles.

One group per file, "GS-IBL Light Volume", made by Python from the core's numbers (``shader_constants``: box,
shape, tile counts, map sizes, biases) and its three packed float images: the irradiance and visibility atlases
(Closest texels blended here in EEVEE: its Linear filter reads a coarser mip level wherever the coordinates jump
between neighbouring pixels, as they do at a cell's boundary when the corner probes change) and the cells image
(one Closest texel a cell of the grid: its brick's first probe and r; the corners are the brick's sub-cell's where
r > 1). Inputs: Position and Normal
(world space); outputs: Irradiance (E/pi, the core's sample_packed term for term: normal bias, eight corners'
trilinear x Chebyshev weights with DDGI's crush, octahedral lookups with the atlas's borders) and
Inside: 1 inside the volume's box, falling linearly to 0 one node spacing outside it, where the local-light group
(blender/lighting/local_light.py) hands the mesh back to the World's light.

Of the core's formula, two terms are written in a form that nodes have: ``w < CRUSH ? w^3 / CRUSH^2 : w`` is
``min(w, w^3 / CRUSH^2)`` (the same number: w^3 / CRUSH^2 < w exactly where w < CRUSH), and the Chebyshev test's
``r <= m ? 1 : ...`` is ``max(..., 1 - (r > m))``, and the corner's probe index ``r > 1 ? brick : grid`` is
``grid + (r > 1) (brick - grid)``. A bilinear lookup's fraction is the same in every tile (tile
origins are whole texels), so the normal's is computed once for the eight irradiance lookups.

Each group reads its eight corners through eight instances of one corner group ("... Corner"): Python makes nodes at
a cost that grows with the tree's size (one flat group of ~1,200 nodes took 6 s to make on a 2-core CPU; the two
trees of ~110 nodes each take 0.1 s). A new bake does not make them again: the nodes do not change with the volume,
and every number that does is one shared node (NodeMath.param) whose value is set (~0.02 s a bake).

The images and the group's numbers live in datablocks (the images packed, the spec as JSON on the irradiance
image), so the group follows undo and save/reload like the local-light group.
"""
from __future__ import annotations

import json

import bpy
import numpy as np

from ...core.probe import volume as pv
from ...core.probe.grid import GridSpec
from ..common.datablocks import MARKER, find_ours, packed_float_image
from .node_math import Mismatch, NodeMath

# one group per engine: Cycles reads Linear texels (Closest texels blended in nodes overflowed its shader stack, the
# visibility's lookups most: "out of SVM stack space" at eight corners, and the shader rendered black), EEVEE reads
# Closest texels blended in nodes (its Linear filter: 5% at the 95th percentile, 20% at worst, a coarser mip level
# where the corner probes change between neighbouring pixels; Closest: 0.4%, 3.3%)
GROUPS = {"CYCLES": ("GS-IBL Light Volume", "light_volume", True),
          "EEVEE": ("GS-IBL Light Volume EEVEE", "light_volume_eevee", False)}
IRRADIANCE_ROLE, VISIBILITY_ROLE, CELLS_ROLE = "volume_irradiance", "volume_visibility", "volume_cells"
IRRADIANCE_IMAGE, VISIBILITY_IMAGE = "GS-IBL Volume Irradiance", "GS-IBL Volume Visibility"
CELLS_IMAGE = "GS-IBL Volume Cells"
SPEC = "gs_ibl_volume_spec"  # irradiance image custom property: JSON {"lo", "hi", "shape", "tiles"}


def volume_image() -> bpy.types.Image | None:
    """The file's volume irradiance atlas (its custom properties hold the spec and the World's numbers)."""
    return find_ours(bpy.data.images, IRRADIANCE_ROLE)


def visibility_image() -> bpy.types.Image | None:
    return find_ours(bpy.data.images, VISIBILITY_ROLE)


def cells_image() -> bpy.types.Image | None:
    return find_ours(bpy.data.images, CELLS_ROLE)


def _stored(image: bpy.types.Image | None) -> dict | None:
    """The JSON the irradiance image holds (SPEC), None without a volume."""
    img = image if image is not None else volume_image()
    raw = img.get(SPEC) if img is not None else None
    return json.loads(raw) if raw else None


def volume_spec(image: bpy.types.Image | None = None) -> GridSpec | None:
    """The GridSpec the file's volume was baked on (None: no volume)."""
    d = _stored(image)
    return None if d is None else GridSpec(tuple(d["lo"]), tuple(d["hi"]), tuple(d["shape"]))


def volume_tiles(image: bpy.types.Image | None = None) -> int | None:
    """The maps in the file's atlases (the grid's probes and the bricks')."""
    d = _stored(image)
    return None if d is None else d.get("tiles")


def volume_group(engine: str = "CYCLES") -> bpy.types.ShaderNodeTree | None:
    """The file's volume group for ``engine`` ("CYCLES" or "EEVEE"), built for its images when missing (None: the
    file has no volume)."""
    tree = find_ours(bpy.data.node_groups, GROUPS[engine][1])
    if tree is not None:
        return tree
    irr, vis, cells, spec = volume_image(), visibility_image(), cells_image(), volume_spec()
    if irr is None or vis is None or spec is None:
        return None
    if cells is None:  # a file baked before bricks: every cell its grid's own
        cells = packed_float_image(pv.pack_cells(pv.LightVolume(spec, None, None)), None, CELLS_ROLE, CELLS_IMAGE)
    return build_groups(irr, vis, cells, spec, volume_tiles(irr))[engine]


def build_groups(irr: bpy.types.Image, vis: bpy.types.Image, cells: bpy.types.Image, spec: GridSpec,
                 tiles: int | None = None) -> dict:
    """(Re)build the file's volume groups {engine: group} to read ``irr`` and ``vis`` (pack_atlas's, ``tiles``
    maps; None: the grid's alone) and ``cells`` (pack_cells') on ``spec``."""
    return {engine: _group(engine, irr, vis, cells, spec, tiles) for engine in GROUPS}


# the group's sockets, and its corner group's (one of the eight trilinear corners: its weighted irradiance and
# weight; eight instances of one small group, since making nodes in Python costs in proportion to the tree's size)
SOCKETS = ((("Position", "Vector"), ("Normal", "Vector")), (("Irradiance", "Vector"), ("Inside", "Float")))
CORNER_SOCKETS = ((("Cell", "Vector"), ("L0", "Vector"), ("F", "Vector"), ("Corner", "Vector"), ("P", "Vector"),
                   ("InvR", "Float"), ("Fine", "Float"), ("Side", "Float"), ("FirstBrick", "Float"),
                   ("IrrTexel", "Vector"), ("IrrFrac", "Vector")),
                  (("Term", "Vector"), ("Weight", "Float")))


def _group(engine: str, irr, vis, cells, spec: GridSpec, tiles) -> bpy.types.ShaderNodeTree:
    name, role, linear = GROUPS[engine]
    k = pv.shader_constants(spec, tiles)
    for img, size, what in ((irr, k["irradiance_size"], "irradiance"), (vis, k["visibility_size"], "visibility"),
                            (cells, k["cells_size"], "cells")):
        if tuple(img.size) != tuple(size):
            raise ValueError(f"{img.name!r} is {tuple(img.size)} pixels; the volume's {what} atlas must be {size}")
    corner = _tree(f"{name} Corner", f"{role}_corner", CORNER_SOCKETS)
    _fill(corner, lambda b: _build_corner(b, irr, vis, k, linear))
    tree = _tree(name, role, SOCKETS)
    _fill(tree, lambda b: _build(b, cells, corner, k))
    return tree


def _tree(name: str, role: str, sockets) -> bpy.types.ShaderNodeTree:
    """The file's group of ``role`` with ``sockets`` ((inputs, outputs) of (name, type)), made or its interface
    made again where it differs (an older file's)."""
    tree = find_ours(bpy.data.node_groups, role)
    if tree is None:
        tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
        tree[MARKER] = role
    want = [(n, io, f"NodeSocket{t}") for io, group in zip(("INPUT", "OUTPUT"), sockets) for n, t in group]
    have = [(i.name, i.in_out, i.socket_type) for i in tree.interface.items_tree if i.item_type == "SOCKET"]
    if sorted(have) != sorted(want):
        tree.interface.clear()
        for n, io, t in want:
            tree.interface.new_socket(n, in_out=io, socket_type=t)
    return tree


def _fill(tree, build) -> None:
    """``build(b)`` on ``tree``: updating the nodes an earlier build made (they do not change with the volume,
    only their numbers and images), or making them afresh."""
    if len(tree.nodes):
        try:
            build(NodeMath(tree, reuse=True))
            return
        except Mismatch:
            pass
    tree.nodes.clear()
    build(NodeMath(tree))
    # columns in creation order, rows as tall as the tallest node (a Corner group node: ~420 units), none selected:
    # readable enough, not needed to work (one call each: a node's own set updates the whole tree)
    n = len(tree.nodes)
    tree.nodes.foreach_set("location", [x for j in range(n) for x in (260.0 * (j // 10), -450.0 * (j % 10))])
    tree.nodes.foreach_set("select", [False] * n)


def _oct_uv(b: NodeMath, d):
    """(u, v) in 0..1 of oct_encode(d) * 0.5 + 0.5 (two sockets)."""
    a = b.vval("DOT_PRODUCT", b.vec("ABSOLUTE", d), (1.0, 1.0, 1.0))
    x, y, z = b.separate(d)
    px, py = b.math("DIVIDE", x, a), b.math("DIVIDE", y, a)

    def sign(v):  # +1 at 0, as the core's
        return b.math("MULTIPLY_ADD", b.math("LESS_THAN", v, 0.0), -2.0, 1.0)
    fx = b.math("MULTIPLY", b.math("SUBTRACT", 1.0, b.math("ABSOLUTE", py)), sign(px))
    fy = b.math("MULTIPLY", b.math("SUBTRACT", 1.0, b.math("ABSOLUTE", px)), sign(py))
    below = b.math("LESS_THAN", z, 0.0)
    u = b.math("MULTIPLY_ADD", b.math("SUBTRACT", fx, px), below, px)
    v = b.math("MULTIPLY_ADD", b.math("SUBTRACT", fy, py), below, py)
    return b.math("MULTIPLY_ADD", u, 0.5, 0.5), b.math("MULTIPLY_ADD", v, 0.5, 0.5)


def _in_tile(b: NodeMath, uv, size: int):
    """Within a tile's interior of ``size`` texels: (the lower texel column and row left of and below the lookup,
    counted from the tile's corner, border included; the bilinear fractions)."""
    out = []
    for c in uv:
        x = b.math("MULTIPLY_ADD", c, float(size), 0.5)  # 1 + c size - 0.5: continuous, texel centres at whole
        x0 = b.math("FLOOR", x)
        out.append((x0, b.math("SUBTRACT", x, x0)))
    return out


def _bilinear(b: NodeMath, image, origin, local, texel_size, linear: bool):
    """The bilinear lookup at the tile ``origin`` (column, row sockets) + ``local``: one Linear texture node
    (``linear``), or four Closest texels blended here. ``texel_size``: (1 / width, 1 / height) sockets."""
    (x0, fx), (y0, fy) = local
    ox, oy = origin
    du, dv = texel_size
    if linear:  # pixel / size with the texel centres at +0.5, as the core's _bilinear
        u = b.math("MULTIPLY", b.math("ADD", b.math("ADD", ox, x0), b.math("ADD", fx, 0.5)), du)
        v = b.math("MULTIPLY", b.math("ADD", b.math("ADD", oy, y0), b.math("ADD", fy, 0.5)), dv)
        return b.texel(image, u, v, "Linear")
    xs = [b.math("MULTIPLY", b.math("ADD", b.math("ADD", ox, x0), 0.5 + k), du) for k in (0, 1)]
    ys = [b.math("MULTIPLY", b.math("ADD", b.math("ADD", oy, y0), 0.5 + k), dv) for k in (0, 1)]
    t = {(i, j): b.texel(image, xs[i], ys[j]) for i in (0, 1) for j in (0, 1)}

    def lerp(a, c, f):
        return b.vec("MULTIPLY_ADD", b.vec("SUBTRACT", c, a), b.combine(f, f, f), a)
    return lerp(lerp(t[0, 0], t[1, 0], fx), lerp(t[0, 1], t[1, 1], fx), fy)


def _build(b: NodeMath, cells, corner, k: dict) -> None:
    """The nodes of sample_packed (the module docstring says which terms take another form) for shader_constants
    ``k``, made or updated by ``b``, with eight ``corner`` groups (_build_corner). Every number that changes with
    the volume is one shared node (b.param), so a new bake sets a few dozen values."""
    gin, gout = b.new("NodeGroupInput"), b.new("NodeGroupOutput")
    lo, hi = np.asarray(k["lo"], np.float64), np.asarray(k["hi"], np.float64)
    top = np.asarray(k["shape"], np.float64) - 1
    span = np.where(hi > lo, hi - lo, 1.0)
    ncx, ncy, _ = k["cells"]
    ccols, crows = k["cells_size"]
    P = b.param

    n = b.vec("NORMALIZE", gin.outputs["Normal"])
    p = b.vec("MULTIPLY_ADD", n, P("normal_bias", [k["normal_bias"]] * 3), gin.outputs["Position"])
    g = b.vec("MINIMUM", b.vec("MAXIMUM", b.vec("MULTIPLY", b.vec("SUBTRACT", p, P("lo", lo)),
                                                     P("to_grid", top / span)), (0.0, 0.0, 0.0)), P("top", top))
    # the cell, its brick (the cells image: first brick probe, r) and the sub-cell's corner l0 and fractions
    c = b.vec("MINIMUM", b.vec("FLOOR", g), P("last_cell", np.maximum(top - 1, 0)))
    inv_ccols = P("1/cells_w", 1.0 / ccols)
    cx, cy, cz = b.separate(c)
    ci = b.math("MULTIPLY_ADD", b.math("MULTIPLY_ADD", cz, P("cells_y", float(ncy)), cy), P("cells_x", float(ncx)),
                cx)
    crow = b.math("FLOOR", b.math("MULTIPLY", b.math("ADD", ci, 0.5), inv_ccols))
    ccol = b.math("MULTIPLY_ADD", crow, P("-cells_w", -float(ccols)), ci)
    base, r, _ = b.separate(b.texel(cells, b.math("MULTIPLY", b.math("ADD", ccol, 0.5), inv_ccols),
                                    b.math("MULTIPLY", b.math("ADD", crow, 0.5), P("1/cells_h", 1.0 / crows))))
    local = b.scale(b.vec("SUBTRACT", g, c), r)
    rm1 = b.math("SUBTRACT", r, 1.0)
    l0 = b.vec("MINIMUM", b.vec("FLOOR", local), b.combine(rm1, rm1, rm1))
    f = b.vec("SUBTRACT", local, l0)
    (x0, fx), (y0, fy) = _in_tile(b, _oct_uv(b, n), pv.IRR)
    shared = {"Cell": c, "L0": l0, "F": f, "P": p, "InvR": b.math("DIVIDE", 1.0, r),
              "Fine": b.math("GREATER_THAN", r, 1.0), "Side": b.math("ADD", r, 1.0),
              "FirstBrick": b.math("ADD", base, P("grid_count", float(k["grid_count"]))),
              "IrrTexel": b.combine(x0, y0), "IrrFrac": b.combine(fx, fy)}
    num, den = None, None
    for k_corner in range(8):
        node = b.new("ShaderNodeGroup")
        b.setting(node, "node_tree", corner)
        for name, socket in shared.items():
            b.link(socket, node.inputs[name])
        b.value(node.inputs["Corner"], tuple(float((k_corner >> a) & 1) for a in range(3)))
        term, w = node.outputs["Term"], node.outputs["Weight"]
        num = term if num is None else b.vec("ADD", num, term)
        den = w if den is None else b.math("ADD", den, w)
    b.link(b.vec("DIVIDE", num, b.combine(den, den, den)), gout.inputs["Irradiance"])
    # Inside: 1 in the box, 0 one spacing out (the unbiased position: where the mesh is)
    pos = gin.outputs["Position"]
    out = b.vec("MAXIMUM", b.vec("MAXIMUM", b.vec("SUBTRACT", P("lo", lo), pos), b.vec("SUBTRACT", pos, P("hi", hi))),
                (0.0, 0.0, 0.0))
    ox, oy, oz = b.separate(out)
    far = b.math("MAXIMUM", b.math("MAXIMUM", ox, oy), oz)
    inside = b.math("MULTIPLY_ADD", far, P("-1/spacing", -1.0 / k["spacing"]), 1.0)
    b.setting(inside.node, "use_clamp", True)
    b.link(inside, gout.inputs["Inside"])
    b.finish()


def _build_corner(b: NodeMath, irr, vis, k: dict, linear: bool) -> None:
    """One corner of sample_packed's eight: its probe (grid node or brick probe), the Chebyshev weight from the
    visibility moments along probe -> point, times the trilinear weight; outputs the weighted irradiance and the
    weight. The trilinear weight's factor on an axis, f or 1 - f by the corner's bit, is |1 - bit - f|: the same
    number."""
    gin, gout = b.new("NodeGroupInput"), b.new("NodeGroupOutput")
    g = gin.outputs
    shape = np.asarray(k["shape"], np.float64)
    cols = float(k["cols"])
    (iw, ih), (vw, vh) = k["irradiance_size"], k["visibility_size"]
    P = b.param
    sel = b.separate(b.vec("ABSOLUTE", b.vec("SUBTRACT", b.vec("SUBTRACT", (1.0, 1.0, 1.0), g["Corner"]), g["F"])))
    tri = b.math("MULTIPLY", b.math("MULTIPLY", sel[0], sel[1]), sel[2])
    c, side = g["Cell"], g["Side"]
    ll = b.vec("ADD", g["L0"], g["Corner"])
    # q = first node + (c + L / r) step; the grid's index of node min(c + L, top); the brick's base + L's
    q = b.vec("MULTIPLY_ADD", b.vec("ADD", c, b.scale(ll, g["InvR"])), P("node_step", k["node_step"]),
              P("first_node", k["first_node"]))
    nx_, ny_, nz_ = b.separate(b.vec("MINIMUM", b.vec("ADD", c, ll), P("top", shape - 1)))
    coarse = b.math("MULTIPLY_ADD", b.math("MULTIPLY_ADD", nz_, P("nodes_y", shape[1]), ny_), P("nodes_x", shape[0]),
                    nx_)
    lx, ly, lz = b.separate(ll)
    brick = b.math("ADD", b.math("MULTIPLY_ADD", b.math("MULTIPLY_ADD", lz, side, ly), side, lx), g["FirstBrick"])
    i = b.math("MULTIPLY_ADD", b.math("SUBTRACT", brick, coarse), g["Fine"], coarse)
    row = b.math("FLOOR", b.math("MULTIPLY", b.math("ADD", i, 0.5), P("1/cols", 1.0 / cols)))
    col = b.math("MULTIPLY_ADD", row, P("-cols", -cols), i)
    away = b.vec("SUBTRACT", g["P"], q)
    r = b.vval("LENGTH", away)
    # the moments along probe -> point (+Z where they coincide, as the core's _away)
    away = b.vec("ADD", away, b.combine(0.0, 0.0, b.math("LESS_THAN", r, 1e-12)))
    vt = float(pv.VIS + 2)
    mom = _bilinear(b, vis, (b.math("MULTIPLY", col, vt), b.math("MULTIPLY", row, vt)),
                    _in_tile(b, _oct_uv(b, away), pv.VIS), (P("1/vis_w", 1.0 / vw), P("1/vis_h", 1.0 / vh)), linear)
    m, m2, _ = b.separate(mom)
    var = b.math("MAXIMUM", b.math("SUBTRACT", m2, b.math("MULTIPLY", m, m)),
                 b.math("POWER", b.math("MULTIPLY", m, k["variance_floor"]), 2.0))
    beyond = b.math("MAXIMUM", b.math("SUBTRACT", r, m), 0.0)
    ratio = b.math("DIVIDE", var, b.math("MAXIMUM", b.math("MULTIPLY_ADD", beyond, beyond, var), 1e-30))
    cheb = b.math("MAXIMUM", b.math("POWER", ratio, 3.0), b.math("SUBTRACT", 1.0, b.math("GREATER_THAN", r, m)))
    w = b.math("MAXIMUM", cheb, k["min_weight"])
    w = b.math("MINIMUM", w, b.math("MULTIPLY", b.math("POWER", w, 3.0), 1.0 / k["crush"] ** 2))
    w = b.math("MULTIPLY", w, tri)
    it = float(pv.IRR + 2)
    x0, y0, _ = b.separate(g["IrrTexel"])
    fx, fy, _ = b.separate(g["IrrFrac"])
    e = _bilinear(b, irr, (b.math("MULTIPLY", col, it), b.math("MULTIPLY", row, it)), ((x0, fx), (y0, fy)),
                  (P("1/irr_w", 1.0 / iw), P("1/irr_h", 1.0 / ih)), linear)
    b.link(b.scale(e, w), gout.inputs["Term"])
    b.link(w, gout.inputs["Weight"])
    b.finish()
