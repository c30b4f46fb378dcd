"""Small helpers that add math nodes to a shader node tree, each returning the output socket: the shader twins of
numpy expressions (the local-light group, blender/lighting/local_light.py, and the light volume's,
blender/lighting/volume_nodes.py) are written with them. An argument is a socket, or a plain number / tuple that
becomes the input's value.

Every node is made after the nodes feeding it. Cycles compiles a shader in passes over its nodes in the order they
were made, each pass taking the nodes whose inputs are ready: a node made before its input waits for the next pass
while everything after it is compiled and held, and a volume group with one texture lookup made that way per
corner ran out of Cycles' shader stack ("out of SVM stack space": the material rendered black).

``NodeMath(tree, reuse=True)`` walks a tree an earlier NodeMath built with the same calls and only sets what
differs (operations, values, images): each node made, linked or set from Python updates the whole tree, so making
costs grow with the tree's size (a flat light volume group of ~1,200 nodes took 6 s), and a new bake changes only
numbers. ``param`` gives such a number one node of its own, shared by every node that reads it. Nodes are found
by the names given at creation (the node editor reorders the tree's list when a node is clicked); any difference in
the nodes' kinds or links raises Mismatch, and the caller builds afresh."""
from __future__ import annotations

import numpy as np

PREFIX = "gs"  # node names: PREFIX + creation index


class Mismatch(Exception):
    """The tree is not what these calls built (an older file's group, a user's edit): build it afresh."""


class NodeMath:
    def __init__(self, tree, reuse: bool = False):
        self.tree, self.N, self.L = tree, tree.nodes, tree.links
        self.made = 0
        self._params: dict = {}
        self._old = {n.name: n for n in tree.nodes} if reuse else None

    def new(self, kind: str):
        """A node of ``kind`` (bl_idname): made, or in reuse mode the one made at this point of the calls."""
        name = f"{PREFIX}{self.made}"
        self.made += 1
        if self._old is None:
            node = self.N.new(kind)
            node.name = name
            return node
        node = self._old.get(name)
        if node is None or node.bl_idname != kind:
            raise Mismatch(name)
        return node

    def finish(self) -> None:
        """In reuse mode: the tree holds no node these calls did not make (raises Mismatch)."""
        if self._old is not None and len(self._old) != self.made:
            raise Mismatch(f"{len(self._old)} nodes, {self.made} made")

    def link(self, socket, into) -> None:
        if self._old is None:
            self.L.new(socket, into)
        elif not into.is_linked:
            raise Mismatch(into.node.name)

    def value(self, into, v) -> None:
        """Set an input's value; in reuse mode only where it differs at the input's own (float32) precision."""
        if self._old is not None:
            old = into.default_value
            if np.array_equal(np.asarray(old if isinstance(v, (int, float)) else tuple(old), np.float32),
                              np.asarray(v, np.float32)):
                return
        into.default_value = v

    @staticmethod
    def setting(node, name: str, v) -> None:
        """Set a node's property (an operation, an image) where it differs: every set tags the tree for an update."""
        if getattr(node, name) != v:
            setattr(node, name, v)

    def param(self, name: str, v):
        """A number (or, given three, a vector) the tree's nodes share by a link: one node, named at its first use,
        so that a new value is one set."""
        if name not in self._params:
            if isinstance(v, (int, float)):
                node = self.new("ShaderNodeValue")
                self.value(node.outputs[0], float(v))
            else:
                node = self.new("ShaderNodeCombineXYZ")
                self._set(node, tuple(float(x) for x in v))
            self._params[name] = node.outputs[0]
        return self._params[name]

    def _set(self, node, inputs):
        for i, v in enumerate(inputs):
            if v is None:
                continue
            if isinstance(v, (int, float, tuple)):
                self.value(node.inputs[i], v)
            else:
                self.link(v, node.inputs[i])
        return node.outputs[0]

    def _op(self, kind: str, op: str):
        m = self.new(kind)
        self.setting(m, "operation", op)
        return m

    def math(self, op, *inputs):
        return self._set(self._op("ShaderNodeMath", op), inputs)

    def vec(self, op, *inputs):
        """A Vector Math node; its Vector output (DOT_PRODUCT, LENGTH, DISTANCE: use vval)."""
        m = self._op("ShaderNodeVectorMath", op)
        self._set(m, inputs)
        return m.outputs["Vector"]

    def vval(self, op, *inputs):
        """A Vector Math node giving a number (DOT_PRODUCT, LENGTH, DISTANCE): its Value output."""
        m = self._op("ShaderNodeVectorMath", op)
        self._set(m, inputs)
        return m.outputs["Value"]

    def scale(self, v, s):
        m = self._op("ShaderNodeVectorMath", "SCALE")
        self._set(m, (v,))
        if isinstance(s, (int, float)):
            self.value(m.inputs["Scale"], float(s))
        else:
            self.link(s, m.inputs["Scale"])
        return m.outputs["Vector"]

    def separate(self, v):
        sep = self.new("ShaderNodeSeparateXYZ")
        self.link(v, sep.inputs[0])
        return sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]

    def combine(self, x, y, z=0.0):
        return self._set(self.new("ShaderNodeCombineXYZ"), (x, y, z))

    def const(self, v):
        return self._set(self.new("ShaderNodeCombineXYZ"), tuple(float(x) for x in v))

    def attribute(self, name, kind: str = "Vector"):
        a = self.new("ShaderNodeAttribute")
        self.setting(a, "attribute_type", "OBJECT")
        self.setting(a, "attribute_name", name)
        return a.outputs[kind]

    def texel(self, image, u, v, interpolation: str = "Closest"):
        """The texel of ``image`` under (u, v) in 0..1 (Closest, Extend): callers blend texels themselves, since
        EEVEE's Linear filter read a coarser level where the coordinates jump between neighbouring pixels; or, with
        ``interpolation="Linear"``, the texture unit's own bilinear lookup there."""
        uv = self.combine(u, v)  # made before the texture: Cycles compiles nodes in the order they were made
        tex = self.new("ShaderNodeTexImage")
        self.setting(tex, "image", image)
        self.setting(tex, "interpolation", interpolation)
        self.setting(tex, "extension", "EXTEND")
        self.link(uv, tex.inputs["Vector"])
        return tex.outputs["Color"]
