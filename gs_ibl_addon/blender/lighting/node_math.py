"""Small helpers that add math nodes to a shader node tree, each returning the output socket: the shader twins of
numpy expressions (the local-light group, blender/lighting/local_light.py, and the light volume's,
blender/lighting/volume_nodes.py) are written with them. An argument is a socket, or a plain number / tuple that
becomes the input's value.

Every node is made after the nodes feeding it. Cycles compiles a shader in passes over its nodes in the order they
were made, each pass taking the nodes whose inputs are ready: a node made before its input waits for the next pass
while everything after it is compiled and held, and a volume group with one texture lookup made that way per
corner ran out of Cycles' shader stack ("out of SVM stack space": the material rendered black)."""
from __future__ import annotations


class NodeMath:
    def __init__(self, tree):
        self.tree, self.N, self.L = tree, tree.nodes, tree.links

    def _set(self, node, inputs):
        for i, v in enumerate(inputs):
            if v is None:
                continue
            if isinstance(v, (int, float, tuple)):
                node.inputs[i].default_value = v
            else:
                self.L.new(v, node.inputs[i])
        return node.outputs[0]

    def math(self, op, *inputs):
        m = self.N.new("ShaderNodeMath")
        m.operation = op
        return self._set(m, inputs)

    def vec(self, op, *inputs):
        """A Vector Math node; its Vector output (DOT_PRODUCT, LENGTH, DISTANCE: use vval)."""
        m = self.N.new("ShaderNodeVectorMath")
        m.operation = op
        self._set(m, inputs)
        return m.outputs["Vector"]

    def vval(self, op, *inputs):
        """A Vector Math node giving a number (DOT_PRODUCT, LENGTH, DISTANCE): its Value output."""
        m = self.N.new("ShaderNodeVectorMath")
        m.operation = op
        self._set(m, inputs)
        return m.outputs["Value"]

    def scale(self, v, s):
        m = self.N.new("ShaderNodeVectorMath")
        m.operation = "SCALE"
        self._set(m, (v,))
        if isinstance(s, (int, float)):
            m.inputs["Scale"].default_value = float(s)
        else:
            self.L.new(s, m.inputs["Scale"])
        return m.outputs["Vector"]

    def separate(self, v):
        sep = self.N.new("ShaderNodeSeparateXYZ")
        self.L.new(v, sep.inputs[0])
        return sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]

    def combine(self, x, y, z=0.0):
        c = self.N.new("ShaderNodeCombineXYZ")
        return self._set(c, (x, y, z))

    def const(self, v):
        c = self.N.new("ShaderNodeCombineXYZ")
        for i, x in enumerate(v):
            c.inputs[i].default_value = float(x)
        return c.outputs[0]

    def attribute(self, name, kind: str = "Vector"):
        a = self.N.new("ShaderNodeAttribute")
        a.attribute_type, a.attribute_name = "OBJECT", name
        return a.outputs[kind]

    def texel(self, image, u, v, interpolation: str = "Closest"):
        """The texel of ``image`` under (u, v) in 0..1 (Closest, Extend): callers blend texels themselves, since
        EEVEE's Linear filter read a coarser level where the coordinates jump between neighbouring pixels; or, with
        ``interpolation="Linear"``, the texture unit's own bilinear lookup there."""
        uv = self.combine(u, v)  # made before the texture: Cycles compiles nodes in the order they were made
        tex = self.N.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = interpolation
        tex.extension = "EXTEND"
        self.L.new(uv, tex.inputs["Vector"])
        return tex.outputs["Color"]
