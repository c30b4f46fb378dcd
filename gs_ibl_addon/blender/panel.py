"""Probe operators (add, bake/refresh, restore World) and the 3D Viewport sidebar panel "GS-IBL"."""
from __future__ import annotations

import time

import bpy
import numpy as np
from bpy.props import EnumProperty
from mathutils import Vector

from . import world as gw
from .properties import PROBE_NAME, is_probe
from .splat_object import is_splat_object, scene_from_object


def find_probe(context) -> bpy.types.Object | None:
    obj = context.active_object
    if is_probe(obj):
        return obj
    return next((o for o in context.scene.objects if is_probe(o)), None)


def find_splats(context, probe=None) -> bpy.types.Object | None:
    if probe is not None and probe.gs_ibl_probe.splats is not None:
        return probe.gs_ibl_probe.splats
    obj = context.active_object
    if is_splat_object(obj):
        return obj
    found = [o for o in context.scene.objects if is_splat_object(o)]
    return found[0] if len(found) == 1 else None


class GSIBL_OT_add_probe(bpy.types.Operator):
    """Add a GS-IBL light probe (an Empty) at the 3D cursor or at the selected mesh"""
    bl_idname = "gs_ibl.add_probe"
    bl_label = "Add GS-IBL Probe"
    bl_options = {"REGISTER", "UNDO"}

    place: EnumProperty(name="Place", default="AUTO",
                        items=[("AUTO", "Auto", "At the selected mesh if there is one, else at the 3D cursor"),
                               ("CURSOR", "3D Cursor", "At the 3D cursor"),
                               ("SELECTED", "Selected Mesh", "At the centre of the selected mesh's bounds")])

    def execute(self, context):
        target = context.active_object if context.active_object and context.active_object.type == "MESH" \
            and not is_splat_object(context.active_object) else None
        if self.place == "SELECTED" and target is None:
            self.report({"ERROR"}, "Select a mesh to place the probe at (or place it at the 3D cursor)")
            return {"CANCELLED"}
        if self.place != "CURSOR" and target is not None:
            corners = [target.matrix_world @ Vector(c) for c in target.bound_box]
            location = sum(corners, Vector()) / 8.0
        else:
            location = context.scene.cursor.location.copy()
        splats = find_splats(context)
        probe = bpy.data.objects.new(PROBE_NAME, None)
        probe.empty_display_type = "SPHERE"
        probe.empty_display_size = 0.25
        probe.location = location
        probe.gs_ibl_probe.is_probe = True
        probe.gs_ibl_probe.splats = splats
        context.collection.objects.link(probe)
        for o in context.view_layer.objects.selected:
            o.select_set(False)
        probe.select_set(True)
        context.view_layer.objects.active = probe
        return {"FINISHED"}


def _latlong(result, kind: str, height: int) -> np.ndarray:
    """A (height, 2*height, 3) lat-long of the result's ``kind`` ("radiance" or "irradiance").

    Takes the result's own lat-long if it has one, else resamples its cube (core.probe.ProbeResult keeps
    cubes in ``radiance`` / ``irradiance``) with the core's seamless bilinear cube_to_latlong.
    """
    ll = getattr(result, f"{kind}_latlong", None)
    if callable(ll):
        ll = ll(height)
    if ll is None:
        cube = getattr(result, kind, None)
        if cube is None:
            raise ValueError(f"the probe result has no {kind} map")
        from ..core.probe.latlong import cube_to_latlong
        ll = cube_to_latlong(np.asarray(cube, np.float32), 2 * height, height)
    return np.asarray(ll, np.float32)[..., :3]


def _import_bake_probe():
    """The core's bake_probe(scene, probe_position, settings), wherever the core exposes it."""
    try:
        from ..core.probe import bake_probe
    except ImportError:
        from ..core.bake import bake_probe  # noqa: F401  (raises ImportError when neither exists)
    return bake_probe


def apply_probe_images(context, probe: bpy.types.Object, radiance: np.ndarray,
                       irradiance: np.ndarray | None) -> bpy.types.World:
    """Write baked lat-long maps into our images, World and irradiance node group, per the probe's settings."""
    s = probe.gs_ibl_probe
    scene = context.scene
    rad_img = gw.latlong_image("radiance", radiance, pack=s.pack_images)
    if irradiance is not None:
        gw.irradiance_group(gw.latlong_image("irradiance", irradiance, pack=s.pack_images))
    # The camera keeps what it saw before we first took over the World.
    previous = scene.get(gw.PREVIOUS_WORLD)
    if not isinstance(previous, bpy.types.World):
        previous = scene.world if scene.world is not None and scene.world.get(gw.MARKER) != "world" else None
    world = gw.build_world(rad_img, s.strength, s.keep_background, previous)
    if s.assign_world:
        gw.use_world(scene, world)
    return world


def _core_settings(props):
    """The core's settings object built from the probe's properties (only the fields the core declares)."""
    from ..core import probe as core_probe
    values = {"method": props.method.lower(), "face_size": props.face_size,
              "irradiance_size": props.irradiance_size, "tolerance": props.tolerance}
    cls = getattr(core_probe, "ProbeSettings", None)
    if cls is None:
        return values
    fields = getattr(cls, "__dataclass_fields__", None)
    return cls(**{k: v for k, v in values.items() if fields is None or k in fields})


class GSIBL_OT_bake_probe(bpy.types.Operator):
    """Render the splats' light from the probe and write it into the GS-IBL World (bake or refresh)"""
    bl_idname = "gs_ibl.bake_probe"
    bl_label = "Bake Probe"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def execute(self, context):
        probe = find_probe(context)
        splats = find_splats(context, probe)
        if splats is None:
            self.report({"ERROR"}, "No splat object: import a splat file, then pick it in the probe's Splats field")
            return {"CANCELLED"}
        try:
            bake_probe = _import_bake_probe()
        except ImportError as e:
            self.report({"ERROR"}, f"The probe baker (core.probe.bake_probe) is not available in this build: {e}")
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 3)
        t0 = time.perf_counter()
        try:
            scene = scene_from_object(splats)
            wm.progress_update(1)
            result = bake_probe(scene, np.array(probe.matrix_world.translation, np.float64),
                                _core_settings(probe.gs_ibl_probe))
            wm.progress_update(2)
            s = probe.gs_ibl_probe
            # lat-long width >= 4x the face size keeps the resampling from aliasing (core/probe/latlong.py)
            radiance = _latlong(result, "radiance", max(2 * s.face_size, 32))
            irradiance = _latlong(result, "irradiance", s.irradiance_size)
            apply_probe_images(context, probe, radiance, irradiance)
            wm.progress_update(3)
        except (ValueError, RuntimeError, OSError) as e:
            # Core errors carry a complete message (what, where, what to do); no traceback for the user.
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self.report({"INFO"}, f"Baked {scene.count:,} splats into the GS-IBL World in {time.perf_counter() - t0:.2f} s")
        return {"FINISHED"}


class GSIBL_OT_restore_world(bpy.types.Operator):
    """Give the scene back the World it had before the GS-IBL World was assigned"""
    bl_idname = "gs_ibl.restore_world"
    bl_label = "Restore Previous World"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        if not gw.restore_world(context.scene):
            self.report({"WARNING"}, "No previous World is remembered for this scene")
            return {"CANCELLED"}
        return {"FINISHED"}


class GSIBL_PT_panel(bpy.types.Panel):
    bl_label = "GS-IBL"
    bl_idname = "GSIBL_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "GS-IBL"

    def draw(self, context):
        layout = self.layout
        layout.operator("gs_ibl.import_splats", icon="IMPORT")
        obj = context.active_object
        if is_splat_object(obj):
            info = obj["gs_ibl"]
            box = layout.box()
            box.label(text=f"{len(obj.data.vertices):,} splats, SH degree {info.get('sh_degree', '?')}")
            box.label(text=str(info.get("source", "")))
        probe = find_probe(context)
        layout.operator(GSIBL_OT_add_probe.bl_idname, icon="LIGHTPROBE_SPHERE")
        if probe is None:
            return
        s = probe.gs_ibl_probe
        col = layout.column()
        col.use_property_split = True
        col.label(text=probe.name, icon="EMPTY_DATA")
        col.prop(s, "splats")
        col.prop(s, "method")
        col.prop(s, "face_size")
        col.prop(s, "irradiance_size")
        col.prop(s, "tolerance")
        col.prop(s, "strength")
        col.prop(s, "keep_background")
        col.prop(s, "assign_world")
        col.prop(s, "pack_images")
        layout.operator(GSIBL_OT_bake_probe.bl_idname, text="Bake / Refresh", icon="RENDER_STILL")
        if isinstance(context.scene.get(gw.PREVIOUS_WORLD), bpy.types.World):
            layout.operator(GSIBL_OT_restore_world.bl_idname, icon="LOOP_BACK")


def menu_add(self, context):
    self.layout.operator(GSIBL_OT_add_probe.bl_idname, text="GS-IBL Probe", icon="LIGHTPROBE_SPHERE")


CLASSES = (GSIBL_OT_add_probe, GSIBL_OT_bake_probe, GSIBL_OT_restore_world, GSIBL_PT_panel)
MENUS = ((bpy.types.VIEW3D_MT_add, menu_add),)
