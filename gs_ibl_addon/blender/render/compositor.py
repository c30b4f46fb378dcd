"""Our nodes in the scene's compositor, per Blender version, added to the user's tree and taken out again.

For each Render Layers node of the scene: Render Layers.Image -> Alpha Over (background BEHIND, foreground the
render) -> Alpha Over (background that, foreground FRONT) -> whatever the render's image fed before (the user's own
nodes, or the output). Film Transparent (needed: the render's alpha must be the meshes' coverage) takes the World
out of the render, so where we turned it on, BEHIND goes over the World first: the Environment pass divided by the
share of the pixel it holds (``_world``). A user who had Film Transparent on keeps a transparent background, and
the render settings' *Transparent* changes that wish later (``set_transparent``); Blender 4.2's EEVEE leaves the
pass black, so there the World is not put back (``world_pass_empty``).
FRONT and BEHIND are float images of ours per view layer (premultiplied, scene-linear) that the frame handler fills
for every frame (frame.py). The user's nodes see meshes and splats as one image, and the view
transform is applied after compositing, to both alike. A File Output node per view layer (Splat Pass setting)
writes FRONT and BEHIND as a multilayer EXR, the splats' own pass for compositors.

Where each version keeps the tree (docs/final-frame.md, section 1): 4.2-4.5 ``scene.use_nodes`` + ``scene.node_tree``
(a Composite node is the output); 5.0+ ``scene.compositing_node_group``, a CompositorNodeTree datablock (a Group
Output is). A scene without a tree gets one of ours (Render Layers -> our nodes -> output).

Nothing of the user's is destroyed: our nodes, images and tree carry the ``gs_ibl`` marker (common/datablocks.py);
``remove`` links the user's sockets back to Render Layers.Image, deletes only what is marked, and puts back the
scene settings we changed (Film Transparent, Compositing, Use Nodes), which ``install`` remembered on the scene.
"""
from __future__ import annotations

import os

import bpy

from ..common.datablocks import MARKER, is_ours

NODE_ROLE = "render_node"  # node[MARKER]; node[PART] says which of ours it is, node[FOR_RL] for which Render Layers
TREE_ROLE = "render_compositor"  # a 5.x compositor node group we made for a scene that had none
FRONT_ROLE, BEHIND_ROLE = "render_front", "render_behind"  # images; image[LAYER] = view layer, image[SCENE] = scene
PART, FOR_RL, LAYER, SCENE = "gs_ibl_part", "gs_ibl_render_layers", "gs_ibl_view_layer", "gs_ibl_scene"
STATE = "gs_ibl_render_state"  # on the scene: what install changed, to put back ({setting: previous value})
PASS_FILE_STEM = "splats_"
ENV_PASS = "use_pass_environment:"  # STATE key + view layer name: the Environment pass we turned on there


def new_api(scene) -> bool:
    """Blender 5.0+: the compositor is a node group datablock with a Group Output."""
    return hasattr(scene, "compositing_node_group")


def tree_of(scene):
    """The scene's compositor node tree, or None."""
    if new_api(scene):
        return scene.compositing_node_group
    return scene.node_tree if scene.use_nodes else None


def output_size(scene) -> tuple[int, int]:
    """The size of the composited frame: the resolution at its percentage, or the render border's window when
    cropped to it (docs/final-frame.md: disprect = int(border x size))."""
    r = scene.render
    w, h = r.resolution_x * r.resolution_percentage // 100, r.resolution_y * r.resolution_percentage // 100
    if r.use_border and r.use_crop_to_border:
        x0, x1 = int(r.border_min_x * w), int(r.border_max_x * w)
        y0, y1 = int(r.border_min_y * h), int(r.border_max_y * h)
        return max(x1 - x0, 1), max(y1 - y0, 1)
    return max(w, 1), max(h, 1)


# ---- images ----

def find_image(scene, layer: str, role: str):
    for im in bpy.data.images:
        if is_ours(im, role) and im.get(LAYER) == layer and im.get(SCENE) == scene.name:
            return im
    return None


def ensure_images(scene, layer: str):
    """FRONT and BEHIND of ``layer``, made (main thread only) or resized to the output size."""
    w, h = output_size(scene)
    out = []
    for role, part in ((FRONT_ROLE, "Front"), (BEHIND_ROLE, "Behind")):
        im = find_image(scene, layer, role)
        if im is None:
            im = bpy.data.images.new(f"GS-IBL Splats {part} {layer}", w, h, alpha=True, float_buffer=True)
            im[MARKER], im[LAYER], im[SCENE] = role, layer, scene.name
            im.generated_color = (0.0, 0.0, 0.0, 0.0)
        elif tuple(im.size) != (w, h):
            im.scale(w, h)
        out.append(im)
    return out


# ---- nodes ----

def _ours(node, part: str | None = None) -> bool:
    return node.get(MARKER) == NODE_ROLE and (part is None or node.get(PART) == part)


def _new(tree, idname: str, part: str, rl_name: str, location) -> bpy.types.Node:
    n = tree.nodes.new(idname)
    n[MARKER], n[PART], n[FOR_RL] = NODE_ROLE, part, rl_name
    n.location = location
    n.label = f"GS-IBL {part.replace('_', ' ')}"
    return n


def _alpha_over(tree, new5: bool, bg, fg, part: str, rl_name: str, location):
    n = _new(tree, "CompositorNodeAlphaOver", part, rl_name, location)
    if new5:  # inputs Background, Foreground, Factor, Type, Straight Alpha
        tree.links.new(bg, n.inputs["Background"])
        tree.links.new(fg, n.inputs["Foreground"])
    else:  # Fac, Image (background), Image_001 (foreground); premultiplied over by default
        tree.links.new(bg, n.inputs[1])
        tree.links.new(fg, n.inputs[2])
    return n


def render_layers_nodes(scene, tree) -> list:
    """The tree's Render Layers nodes that render this scene's view layers."""
    return [n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers" and not n.mute
            and (n.scene is None or n.scene == scene) and n.layer in scene.view_layers]


def _made_tree(scene):
    """A compositor of ours for a scene that had none: Render Layers -> output."""
    new5 = new_api(scene)
    if new5:
        tree = bpy.data.node_groups.new("GS-IBL Compositing", "CompositorNodeTree")
        tree[MARKER] = TREE_ROLE
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        out = tree.nodes.new("NodeGroupOutput")
        scene.compositing_node_group = tree
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        for n in [n for n in tree.nodes if n.bl_idname in ("CompositorNodeRLayers", "CompositorNodeComposite")]:
            tree.nodes.remove(n)  # Blender's default pair, made by use_nodes: ours is the same, marked
        out = tree.nodes.new("CompositorNodeComposite")
        out.use_alpha = True
    out[MARKER], out[PART], out[FOR_RL] = NODE_ROLE, "output", ""
    out.location = (900, 0)
    rl = tree.nodes.new("CompositorNodeRLayers")
    rl[MARKER], rl[PART], rl[FOR_RL] = NODE_ROLE, "render_layers", ""
    rl.location = (-300, 0)
    rl.layer = scene.view_layers[0].name
    tree.links.new(rl.outputs["Image"], out.inputs[0])
    return tree


def pass_directory(scene) -> str:
    settings = getattr(scene, "gs_ibl_render", None)
    path = getattr(settings, "pass_path", "") or "//splat_pass/"
    return path


def _set_pass_path(scene, fo, layer: str) -> None:
    stem = f"{PASS_FILE_STEM}{bpy.path.clean_name(layer)}_"
    if new_api(scene):
        if fo.directory != pass_directory(scene) or fo.file_name != stem:
            fo.directory, fo.file_name = pass_directory(scene), stem
    elif fo.base_path != os.path.join(pass_directory(scene), stem):
        fo.base_path = os.path.join(pass_directory(scene), stem)


def _wire_file_output(scene, tree, new5: bool, rl, front, behind):
    fo = _new(tree, "CompositorNodeOutputFile", "file", rl.name, (rl.location.x + 900, rl.location.y - 400))
    fo.format.file_format = "OPEN_EXR_MULTILAYER"
    fo.format.color_depth = "32"
    _set_pass_path(scene, fo, rl.layer)
    if new5:
        for name, src in (("front", front), ("behind", behind)):
            item = fo.file_output_items.new("RGBA", name)
            tree.links.new(src, fo.inputs[item.name])
    else:
        fo.layer_slots.clear()
        for name, src in (("front", front), ("behind", behind)):
            fo.layer_slots.new(name)
            tree.links.new(src, fo.inputs[name])


def shows_world(scene) -> bool:
    """Whether the composite puts the World back under everything: Film Transparent was turned on by us (install
    remembered it) or the user turned *Transparent* off since, not on by the user's wish (a transparent
    background)."""
    return "film_transparent" in scene.get(STATE, {})


def transparent(scene) -> bool:
    """The user's own Film Transparent: before install the setting itself; after, what install found (we keep
    Blender's on while our nodes are in)."""
    if not installed(scene):
        return bool(scene.render.film_transparent)
    return not shows_world(scene)


def set_transparent(scene, value: bool) -> None:
    """The user's Film Transparent (the panel's *Transparent*): with our nodes in, Blender's stays on and this
    decides whether the World is put back, and what removing our nodes leaves (on stays on)."""
    if not installed(scene):
        scene.render.film_transparent = bool(value)
        return
    state = dict(scene.get(STATE, {}))
    if value:
        state.pop("film_transparent", None)
    else:
        state["film_transparent"] = False
    scene[STATE] = state
    _environment_passes(scene)
    sync_world(scene)


def _environment_passes(scene) -> None:
    """The Environment pass on in every rendered view layer where the World is put back (remembered, to restore)."""
    if not shows_world(scene):
        return
    for layer in scene.view_layers:
        if layer.use and not layer.use_pass_environment:
            _remember(scene, f"{ENV_PASS}{layer.name}", False)
            layer.use_pass_environment = True  # the World, which Film Transparent takes out of the render


def world_pass_empty(scene) -> bool:
    """Blender 4.2's EEVEE leaves the Environment pass black under Film Transparent (Cycles in every version and
    EEVEE from 5.0 fill it: docs/final-frame.md section 10): the World is not put back there."""
    return bpy.app.version < (5, 0, 0) and scene.render.engine.startswith("BLENDER_EEVEE")


def _env_output(rl):
    return rl.outputs.get("Env") or rl.outputs.get("Environment")  # 4.2: Env; 5.x: Environment


def _by_id(sockets, identifier: str):
    """A socket by identifier: the Mix node's sockets share their names across its data types."""
    return next(sk for sk in sockets if sk.identifier == identifier)


def _world(tree, new5: bool, rl, behind_out):
    """BEHIND over the World as the camera sees it. The Environment pass holds the World weighted by the share of
    the pixel no surface covers (1 - the render's alpha: a mesh edge's pixel holds both), so it is divided by that
    share first: the render, laid over this, brings its own share back (exact at anti-aliased edges; where a mesh
    covers the pixel the pass is 0 and so is the quotient)."""
    x, y = rl.location.x, rl.location.y
    inv = _new(tree, "CompositorNodeInvert", "world_share", rl.name, (x + 300, y - 800))
    tree.links.new(rl.outputs["Alpha"], inv.inputs[1])  # Color: (a, a, a) -> (1 - a, ...)
    if new5:
        div = _new(tree, "ShaderNodeMix", "world_unweighted", rl.name, (x + 450, y - 700))
        div.data_type, div.blend_type, div.clamp_result = "RGBA", "DIVIDE", False
        _by_id(div.inputs, "Factor_Float").default_value = 1.0
        a, b = _by_id(div.inputs, "A_Color"), _by_id(div.inputs, "B_Color")
        out = _by_id(div.outputs, "Result_Color")
    else:
        div = _new(tree, "CompositorNodeMixRGB", "world_unweighted", rl.name, (x + 450, y - 700))
        div.blend_type, div.use_clamp = "DIVIDE", False
        div.inputs[0].default_value = 1.0
        a, b, out = div.inputs[1], div.inputs[2], div.outputs[0]
    tree.links.new(_env_output(rl), a)
    tree.links.new(inv.outputs[0], b)
    return _alpha_over(tree, new5, out, behind_out, "over_world", rl.name, (x + 550, y - 450)).outputs["Image"]


def _wire(scene, tree, rl, write_pass: bool) -> None:
    """Our nodes between ``rl``.Image and whatever it fed."""
    new5 = new_api(scene)
    front_im, behind_im = ensure_images(scene, rl.layer)
    x, y = rl.location.x, rl.location.y
    imgs = []
    for k, (part, im) in enumerate((("behind_image", behind_im), ("front_image", front_im))):
        n = _new(tree, "CompositorNodeImage", part, rl.name, (x + 300, y - 300 - 250 * k))
        n.image = im
        imgs.append(n)
    image_out = rl.outputs["Image"]
    fed = [lk.to_socket for lk in tree.links if lk.from_socket == image_out]
    mid = _alpha_over(tree, new5, imgs[0].outputs["Image"], image_out, "over_behind", rl.name, (x + 550, y))
    top = _alpha_over(tree, new5, mid.outputs["Image"], imgs[1].outputs["Image"], "over_front", rl.name,
                      (x + 750, y))
    for sock in fed:
        tree.links.new(top.outputs["Image"], sock)  # replaces the link from the render (one link per input)
    _sync_world(scene, tree, rl)
    if write_pass:
        _wire_file_output(scene, tree, new5, rl, imgs[1].outputs["Image"], imgs[0].outputs["Image"])


_WORLD_PARTS = ("world_share", "world_unweighted", "over_world")


def _sync_world(scene, tree, rl) -> bool:
    """The World chain under BEHIND in ``rl``'s nodes where it is wanted (shows_world, and a pass that holds it),
    taken out where not (the engine or the Film Transparent choice changed). True if anything changed."""
    ours = {n.get(PART): n for n in tree.nodes if _ours(n) and n.get(FOR_RL) == rl.name}
    if "over_behind" not in ours or "behind_image" not in ours:
        return False
    want = shows_world(scene) and not world_pass_empty(scene)
    if want == ("over_world" in ours):
        return False
    new5 = new_api(scene)
    bg = ours["over_behind"].inputs["Background" if new5 else 1]
    behind = ours["behind_image"].outputs["Image"]
    if want:
        tree.links.new(_world(tree, new5, rl, behind), bg)
    else:
        for part in _WORLD_PARTS:
            if part in ours:
                tree.nodes.remove(ours[part])
        tree.links.new(behind, bg)
    return True


def sync_world(scene) -> None:
    """The World chain of every wired Render Layers node as the scene's engine wants it now (main thread: a
    depsgraph update of the scene, install)."""
    tree = tree_of(scene)
    if tree is None:
        return
    for rl in render_layers_nodes(scene, tree):
        _sync_world(scene, tree, rl)


def installed(scene) -> bool:
    tree = tree_of(scene)
    return tree is not None and any(_ours(n, "over_front") for n in tree.nodes)


def _remember(scene, key: str, value) -> None:
    state = dict(scene.get(STATE, {}))
    if key not in state:
        state[key] = value
        scene[STATE] = state


def install(scene, write_pass: bool = False) -> None:
    """Our nodes in the scene's compositor for every Render Layers node not yet wired (main thread; idempotent),
    Film Transparent and Compositing on. A scene with no tree gets one of ours."""
    r = scene.render
    if not r.film_transparent:
        _remember(scene, "film_transparent", False)
        r.film_transparent = True  # the render's alpha must be the meshes' coverage
    if not r.use_compositing:
        _remember(scene, "use_compositing", False)
        r.use_compositing = True
    tree = tree_of(scene)
    if tree is None:
        if not new_api(scene):
            _remember(scene, "use_nodes", False)
            if scene.node_tree is not None and len(scene.node_tree.nodes):
                scene.use_nodes = True  # a tree the user switched off: on again, with ours in it
                tree = scene.node_tree
        if tree is None:
            _remember(scene, "made_tree", True)
            tree = _made_tree(scene)
    for layer in scene.view_layers:
        if layer.use:
            ensure_images(scene, layer.name)
    _environment_passes(scene)
    wired = {n.get(FOR_RL) for n in tree.nodes if _ours(n, "over_front")}
    has_file = {n.get(FOR_RL) for n in tree.nodes if _ours(n, "file")}
    for rl in render_layers_nodes(scene, tree):
        if rl.name not in wired:
            _wire(scene, tree, rl, write_pass)
            continue
        _sync_world(scene, tree, rl)
        if write_pass and rl.name not in has_file:
            front = next(n for n in tree.nodes if _ours(n, "front_image") and n.get(FOR_RL) == rl.name)
            behind = next(n for n in tree.nodes if _ours(n, "behind_image") and n.get(FOR_RL) == rl.name)
            _wire_file_output(scene, tree, new_api(scene), rl, front.outputs["Image"], behind.outputs["Image"])
        elif not write_pass and rl.name in has_file:
            for n in [n for n in tree.nodes if _ours(n, "file") and n.get(FOR_RL) == rl.name]:
                tree.nodes.remove(n)
        elif write_pass:
            for n in tree.nodes:
                if _ours(n, "file") and n.get(FOR_RL) == rl.name:
                    _set_pass_path(scene, n, rl.layer)


def remove(scene) -> None:
    """Everything install did, undone: the user's sockets fed by Render Layers.Image again, our nodes, images and
    tree deleted, the scene settings we changed put back."""
    tree = tree_of(scene) if new_api(scene) else scene.node_tree
    if tree is not None:
        for top in [n for n in tree.nodes if _ours(n, "over_front")]:
            rl = tree.nodes.get(top.get(FOR_RL, ""))
            for lk in [lk for lk in tree.links if lk.from_node == top]:
                sock = lk.to_socket
                if rl is not None and not _ours(lk.to_node):
                    tree.links.new(rl.outputs["Image"], sock)
                else:
                    tree.links.remove(lk)
        for n in [n for n in tree.nodes if _ours(n) and n.get(PART) not in ("output", "render_layers")]:
            tree.nodes.remove(n)
    state = dict(scene.get(STATE, {}))
    if state.get("made_tree") and tree is not None:
        if new_api(scene):
            if is_ours(tree, TREE_ROLE):
                scene.compositing_node_group = None
                if tree.users == 0:
                    bpy.data.node_groups.remove(tree)
        else:
            for n in [n for n in tree.nodes if _ours(n)]:
                tree.nodes.remove(n)
    elif tree is not None:  # a tree of the user's: our Render Layers / output only if nothing else uses them
        for n in [n for n in tree.nodes if _ours(n)]:
            tree.nodes.remove(n)
    if "use_nodes" in state and not new_api(scene):
        scene.use_nodes = state["use_nodes"]
    r = scene.render
    if "film_transparent" in state:
        r.film_transparent = bool(state["film_transparent"])
    if "use_compositing" in state:
        r.use_compositing = bool(state["use_compositing"])
    for layer in scene.view_layers:
        if f"{ENV_PASS}{layer.name}" in state:
            layer.use_pass_environment = bool(state[f"{ENV_PASS}{layer.name}"])
    if STATE in scene:
        del scene[STATE]
    for im in [im for im in bpy.data.images if (is_ours(im, FRONT_ROLE) or is_ours(im, BEHIND_ROLE))
               and im.get(SCENE) == scene.name]:
        bpy.data.images.remove(im)
