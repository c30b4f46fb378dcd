"""Clicking splats in the 3D View: the 3D cursor placed on them (Shift+right-click) and their object selected.

Blender finds what is under the mouse by drawing the scene again, depth only (ED_view3d_autodist for the cursor) or
with selection ids (view3d.select); a POST_VIEW handler takes part in neither, and while the overlay shows a splat
object draws nothing of its own (overlay.hide_helpers). So the cursor fell through the splat floor onto the view
plane through its old place, and a splat object could not be clicked. Two operators of ours sit in front of
Blender's in the same keymaps (add-on keymap items come first): they look up the splats under the mouse in the image
the overlay last drew in that region (overlay.splats_under_mouse, overlay_math.splat_hit: distance along the view
axis, bilinear between the pixels that hold splats) and the nearest mesh along the same ray (Scene.ray_cast); when
the splats are nearer (overlay_math.splats_win: the rule the draw uses) they act on the splats, otherwise they pass
the event on to Blender's operator, unchanged.

- GSIBL_OT_cursor3d: puts the cursor at the splat surface point, then lets view3d.cursor3d (without depth) finish
  the job: it projects the mouse onto the view plane through the cursor, which is that point, and applies the
  orientation option and Blender's own notifiers.
- GSIBL_OT_select: runs view3d.select first; if it picked an object that is not behind the splats (a probe's or an
  empty's wires drawn in front of them, a mesh in front) that stands; otherwise the selection goes back to what it
  was and the splat object is selected by the same rules (click, Shift+click toggles).

The keymap items copy the event and options of Blender's own items for those operators in the active keyconfig
(so a right-click-select keymap gets its own events), in the 3D View keymap and the tool keymaps that have them.
"""
from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty

from . import overlay
from .overlay_math import mouse_ray, splats_win
from ..splats.object import is_splat_object

KEYMAPS = ("3D View", "3D View Tool: Tweak", "3D View Tool: Select Box", "3D View Tool: Select Circle",
           "3D View Tool: Select Lasso", "3D View Tool: Cursor")
_SELECT_OPTIONS = ("extend", "deselect", "toggle", "deselect_all")
_keymap_items: list[tuple] = []
last_pick: dict = {}  # what the last click found (tests and the GUI check read it)


def _view3d_window(context) -> bool:
    return (context.area is not None and context.area.type == "VIEW_3D" and context.region is not None
            and context.region.type == "WINDOW" and context.region_data is not None)


def mesh_distance(context, origin: np.ndarray, direction: np.ndarray, limit: float) -> float | None:
    """Distance along the ray to the nearest mesh face of the scene's visible objects (None: none before limit)."""
    from mathutils import Vector
    hit, location, _n, _i, obj, _m = context.scene.ray_cast(context.evaluated_depsgraph_get(), Vector(origin),
                                                             Vector(direction), distance=float(limit))
    if not hit or (obj is not None and is_splat_object(obj)):
        return None
    return float((np.array(location) - origin) @ direction)


def splat_pick(context, x: float, y: float):
    """(splat object, SplatHit) when the splats are what region pixel (x, y) points at, else None."""
    found = overlay.splats_under_mouse(context, x, y)
    last_pick.clear()
    if found is None:
        last_pick.update(splats=None)
        return None
    obj, hit = found
    rv3d, region = context.region_data, context.region
    origin, direction = mouse_ray(np.array(rv3d.view_matrix), np.array(rv3d.window_matrix), region.width,
                                  region.height, x, y)
    mesh = mesh_distance(context, origin, direction, hit.distance * 1.5 + 1.0)
    wins = splats_win(hit.distance, mesh)
    last_pick.update(splats=obj.name, point=tuple(map(float, hit.point)), distance=hit.distance, mesh=mesh,
                     splats_win=wins, mouse=(x, y))
    return (obj, hit) if wins else None


class GSIBL_OT_cursor3d(bpy.types.Operator):
    """Set the 3D cursor on the splats under the mouse (GS-IBL overlay); elsewhere Blender's Set 3D Cursor"""
    bl_idname = "gs_ibl.cursor3d"
    bl_label = "Set 3D Cursor (Splats)"
    bl_options = {"INTERNAL"}

    use_depth: BoolProperty(name="Surface Project", default=True)
    orientation: EnumProperty(name="Orientation", default="VIEW",
                              items=[("NONE", "None", ""), ("VIEW", "View", ""), ("XFORM", "Transform", ""),
                                     ("GEOM", "Geometry", "")])

    @classmethod
    def poll(cls, context):
        return _view3d_window(context)

    def invoke(self, context, event):
        if not self.use_depth:
            return {"PASS_THROUGH"}
        picked = splat_pick(context, event.mouse_region_x, event.mouse_region_y)
        if picked is None:
            return {"PASS_THROUGH"}
        context.scene.cursor.location = picked[1].point
        # the view plane through the cursor meets the mouse ray at the splat point: Blender finishes the job
        return bpy.ops.view3d.cursor3d("INVOKE_DEFAULT", use_depth=False, orientation=self.orientation)


def _selection(context) -> tuple[dict, object]:
    return {o: o.select_get() for o in context.view_layer.objects}, context.view_layer.objects.active


def _picked(before: tuple, after: tuple):
    """The object view3d.select acted on, from the selection before and after it (None: it found nothing)."""
    (sel0, act0), (sel1, act1) = before, after
    if act1 is not None and act1 != act0:
        return act1
    newly = [o for o, s in sel1.items() if s and not sel0.get(o, False)]
    if len(newly) == 1:
        return newly[0]
    gone = [o for o, s in sel1.items() if not s and sel0.get(o, False)]
    if len(gone) == 1 and not newly and any(sel1.values()):  # a Shift+click that deselected one object
        return gone[0]
    if act1 is not None and act1 == act0 and sel1.get(act1) and sel0 == sel1:
        return act1  # clicked the active object again
    return None


def _in_front(obj, hit, origin: np.ndarray, direction: np.ndarray, context) -> bool:
    """Whether what view3d.select picked is in front of the splats under the mouse: a mesh by its face along the
    ray (one it picked near the mouse but the ray misses is taken as behind), anything else (wires, empties,
    lights, probes) by its origin's distance."""
    if obj.type == "MESH":
        d = mesh_distance(context, origin, direction, hit.distance * 1.5 + 1.0)
        return d is not None and not splats_win(hit.distance, d)
    d = float((np.array(obj.matrix_world.translation) - origin) @ direction)
    return d < hit.distance


class GSIBL_OT_select(bpy.types.Operator):
    """Select the splat object under the mouse (GS-IBL overlay); elsewhere Blender's Select"""
    bl_idname = "gs_ibl.select"
    bl_label = "Select (Splats)"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    extend: BoolProperty(name="Extend", default=False)
    deselect: BoolProperty(name="Deselect", default=False)
    toggle: BoolProperty(name="Toggle", default=False)
    deselect_all: BoolProperty(name="Deselect On Nothing", default=False)

    @classmethod
    def poll(cls, context):
        return _view3d_window(context) and context.mode == "OBJECT"

    def invoke(self, context, event):
        picked = splat_pick(context, event.mouse_region_x, event.mouse_region_y)
        if picked is None:
            return {"PASS_THROUGH"}
        splats, hit = picked
        if not splats.visible_get() or splats.hide_select:
            return {"PASS_THROUGH"}
        before = _selection(context)
        options = {k: getattr(self, k) for k in _SELECT_OPTIONS}
        try:
            bpy.ops.view3d.select("INVOKE_DEFAULT", **options)
        except RuntimeError:
            pass
        other = _picked(before, _selection(context))
        rv3d, region = context.region_data, context.region
        origin, direction = mouse_ray(np.array(rv3d.view_matrix), np.array(rv3d.window_matrix), region.width,
                                      region.height, event.mouse_region_x, event.mouse_region_y)
        if other is not None and other != splats and _in_front(other, hit, origin, direction, context):
            last_pick.update(selected=other.name, by="blender")
            return {"FINISHED"}
        for obj, was in before[0].items():  # what view3d.select did goes back
            obj.select_set(was)
        context.view_layer.objects.active = before[1]
        select_object(context, splats, **options)
        last_pick.update(selected=splats.name, by="splats")
        return {"FINISHED"}


def select_object(context, obj, extend=False, deselect=False, toggle=False, deselect_all=False) -> None:
    """Object-mode click selection of ``obj``, as view3d.select does it (ed_object_select_pick)."""
    layer = context.view_layer
    if extend:
        obj.select_set(True)
        layer.objects.active = obj
    elif deselect:
        obj.select_set(False)
    elif toggle:
        if obj.select_get() and layer.objects.active == obj:
            obj.select_set(False)
        else:
            obj.select_set(True)
            layer.objects.active = obj
    else:
        for o in context.selected_objects:
            if o != obj:
                o.select_set(False)
        obj.select_set(True)
        layer.objects.active = obj


# ------------------------------------------------------------------------------------------------------ keymaps

def _mirrored_items(keyconfig):
    """(keymap name, Blender's item) for the view3d.select clicks (not the Alt/Ctrl variants: enumerate, centre,
    object) and view3d.cursor3d items of a keyconfig, in the keymaps ours go into."""
    for name in KEYMAPS:
        km = keyconfig.keymaps.get(name)
        if km is None:
            continue
        for kmi in km.keymap_items:
            if not kmi.active:
                continue
            if kmi.idname == "view3d.cursor3d":
                yield name, kmi
            elif kmi.idname == "view3d.select" and kmi.value == "CLICK":
                p = kmi.properties
                if not any(getattr(p, k, False) for k in ("enumerate", "center", "object")):
                    yield name, kmi


def register_keymaps() -> int:
    """Add our items in front of Blender's (returns how many; none without a window manager's keyconfigs, as in
    background mode)."""
    wm = bpy.context.window_manager
    kcs = getattr(wm, "keyconfigs", None)
    if kcs is None or kcs.addon is None:
        return 0
    source = kcs.active if kcs.active is not None and len(kcs.active.keymaps) else kcs.default
    if source is None:
        return 0
    for name, kmi in list(_mirrored_items(source)):
        km_src = source.keymaps[name]
        km = kcs.addon.keymaps.new(name=name, space_type=km_src.space_type, region_type=km_src.region_type)
        ours = GSIBL_OT_cursor3d if kmi.idname == "view3d.cursor3d" else GSIBL_OT_select
        item = km.keymap_items.new(ours.bl_idname, kmi.type, kmi.value, shift=kmi.shift, ctrl=kmi.ctrl,
                                   alt=kmi.alt, oskey=kmi.oskey, any=kmi.any, key_modifier=kmi.key_modifier)
        names = ("use_depth", "orientation") if ours is GSIBL_OT_cursor3d else _SELECT_OPTIONS
        for prop in names:
            if hasattr(kmi.properties, prop):
                setattr(item.properties, prop, getattr(kmi.properties, prop))
        _keymap_items.append((km, item))
    return len(_keymap_items)


def unregister_keymaps() -> None:
    for km, item in _keymap_items:
        try:
            km.keymap_items.remove(item)
        except (ReferenceError, RuntimeError):
            pass
    _keymap_items.clear()


CLASSES = (GSIBL_OT_cursor3d, GSIBL_OT_select)


def register_picking() -> None:
    """The click operators and their keymap items."""
    for cls in CLASSES:
        if not getattr(cls, "is_registered", False):
            bpy.utils.register_class(cls)
    register_keymaps()


def unregister_picking() -> None:
    unregister_keymaps()
    for cls in reversed(CLASSES):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
