"""The Blender APIs that changed between 4.2 (the manifest's minimum) and 5.3, each behind one function.

Every other module of the extension calls these instead of the changed API, so a new Blender release is fixed
here. What changed, and where it was seen:
- Materials and Worlds: 4.x makes the node tree only when ``use_nodes`` is set; 5.0 always has one and deprecates
  ``use_nodes``.
- Geometry Nodes modifier inputs: up to 5.1 an ID property of the modifier, ``mod[identifier] = value``; from 5.2
  ``mod.properties.inputs.<identifier>.value`` (item assignment raises TypeError), which does not tag the object for
  re-evaluation (seen in 5.2's GUI: the proxy kept drawing until the object was tagged).
- Random Value node: up to 5.1 one output per data type (FLOAT_VECTOR, FLOAT, INT, BOOLEAN) with the unused ones
  disabled; from 5.2 a single output whose type follows ``data_type``.
"""
from __future__ import annotations


def node_tree(idb, clear: bool = False):
    """The node tree of a material or World, made where Blender < 5 has none until use_nodes is set; emptied
    when ``clear``."""
    if idb.node_tree is None:
        idb.use_nodes = True
    if clear:
        idb.node_tree.nodes.clear()
    return idb.node_tree


def _modifier_inputs(mod):
    props = getattr(mod, "properties", None)
    return getattr(props, "inputs", None)  # 5.2+: GeometryNodesInterfaceInputs


def set_modifier_input(mod, identifier: str, value) -> None:
    """Set a Geometry Nodes modifier's input ``identifier`` (the interface socket's identifier, not its name)."""
    inputs = _modifier_inputs(mod)
    if inputs is not None:
        getattr(inputs, identifier).value = value
    else:
        mod[identifier] = value
    mod.id_data.update_tag()  # neither way tags the object for re-evaluation (seen in 5.2's GUI)


def get_modifier_input(mod, identifier: str):
    inputs = _modifier_inputs(mod)
    return getattr(inputs, identifier).value if inputs is not None else mod[identifier]


def modifier_input_identifiers(tree) -> dict[str, str]:
    """Input socket name -> identifier of a Geometry Nodes tree's interface."""
    return {item.name: item.identifier for item in tree.interface.items_tree
            if item.item_type == "SOCKET" and item.in_out == "INPUT"}


def node_output(node, socket_type: str):
    """The enabled output of ``node`` whose type is ``socket_type`` (e.g. a Random Value node's BOOLEAN output)."""
    for s in node.outputs:
        if s.enabled and s.type == socket_type:
            return s
    raise LookupError(f"node {node.bl_idname} has no enabled {socket_type} output "
                      f"({[(s.name, s.type, s.enabled) for s in node.outputs]})")
