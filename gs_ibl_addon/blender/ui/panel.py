"""Probe operators (add, bake/refresh, restore World) and the 3D Viewport sidebar panel "GS-IBL"."""
from __future__ import annotations

import os
import textwrap

import bpy
from bpy.props import BoolProperty, EnumProperty
from mathutils import Vector

from ..lighting import bake as gb
from ..lighting import sources
from ..lighting import world as gw
from ..lighting.stale import animated_text, stale_reasons, stale_text
from ..lighting.stamps import stale_images
from ..common.jobs import JobOperator, running
from ..common.datablocks import PROBE_NAME, is_probe
from ..splats.object import is_native_splats, is_splat_object, splat_count


def find_probe(context) -> bpy.types.Object | None:
    obj = context.active_object
    if is_probe(obj):
        return obj
    return next((o for o in context.scene.objects if is_probe(o)), None)


class GSIBL_OT_add_probe(bpy.types.Operator):
    """Add a GS-IBL light probe (an Empty) at the 3D cursor or at the selected mesh"""
    bl_idname = "gs_ibl.add_probe"
    bl_label = "Add GS-IBL Probe"
    bl_options = {"REGISTER", "UNDO"}

    place: EnumProperty(name="Place", default="AUTO",
                        items=[("AUTO", "Auto", "At the selected mesh if there is one, else at the 3D cursor"),
                               ("CURSOR", "3D Cursor", "At the 3D cursor"),
                               ("SELECTED", "Selected Mesh", "At the centre of the selected mesh's bounds")])
    follow: BoolProperty(name="Follow Mesh", default=True,
                         description="Placed at a mesh: parent the probe to it, so it moves with the mesh (and "
                                     "Update When Moved re-bakes when the mesh moves)")

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
        at_mesh = self.place != "CURSOR" and target is not None
        probe = bpy.data.objects.new(PROBE_NAME, None)
        probe.empty_display_type = "SPHERE"
        probe.empty_display_size = 0.25
        if at_mesh and self.follow:
            probe.parent = target
            probe.matrix_parent_inverse = target.matrix_world.inverted()  # keeps the world place given below
        probe.location = location
        probe.gs_ibl_probe.is_probe = True
        # the splats the probe stands in (of several, the largest holding it); none: the bake asks for one
        probe.gs_ibl_probe.splats = sources.enclosing_splats(context.scene, location)
        context.collection.objects.link(probe)
        for o in context.view_layer.objects.selected:
            o.select_set(False)
        probe.select_set(True)
        context.view_layer.objects.active = probe
        return {"FINISHED"}


class GSIBL_OT_bake_probe(JobOperator, bpy.types.Operator):
    """Render the splats' light from the probe and write it into the GS-IBL World (bake or refresh). From the
    panel it runs beside the UI, with its progress in the status bar; Esc cancels it"""
    bl_idname = "gs_ibl.bake_probe"
    bl_label = "Bake Probe"
    bl_options = {"REGISTER", "UNDO"}
    job_title = "baking"

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def make_job(self, context):
        probe = find_probe(context)
        # a deleted, unlinked, missing or ambiguous splat object is refused before any work
        splats = sources.require_splats(context.scene, probe, context.active_object)
        self._probe_name = probe.name
        return gb.bake_job(context.scene, probe, splats)

    def finished(self, context, result):
        _result, text, warning = result
        probe = context.scene.objects.get(getattr(self, "_probe_name", ""))
        summary = probe.gs_ibl_probe.last_summary if probe is not None and is_probe(probe) else ""
        self.report({"INFO"}, summary or text)  # the status bar's one line; the panel's Details hold the rest
        if warning:
            self.report({"WARNING"}, warning)
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


def _chars_per_line(context) -> int:
    """About how many characters of the UI font fit across the sidebar (for wrapping long text ourselves:
    labels are cut, not wrapped, by Blender)."""
    region = getattr(context, "region", None)
    width = region.width if region is not None else 300
    scale = (context.preferences.system.ui_scale if context.preferences else 1.0) or 1.0  # 0 without a window
    return max(20, int((width - 30 * scale) / (7.0 * scale)))


def wrapped_lines(text: str, chars: int) -> list[str]:
    """``text`` (lines separated by newlines) wrapped at word boundaries to at most ``chars`` characters."""
    out = []
    for line in text.split("\n"):
        out.extend(textwrap.wrap(line, chars, break_long_words=True, break_on_hyphens=False) or [""])
    return out


def _label_block(layout, context, text: str, icon: str = "NONE") -> None:
    col = layout.column(align=True)
    col.scale_y = 0.8  # wrapped lines of one text read as one paragraph
    for i, line in enumerate(wrapped_lines(text, _chars_per_line(context))):
        col.label(text=line, icon=icon if i == 0 else "BLANK1" if icon != "NONE" else "NONE")


def scene_world_hidden(context) -> bool:
    """Material Preview with Scene World off shows an HDRI instead of the scene's World: the baked light is not
    seen there (Rendered mode and Scene World on show it)."""
    shading = getattr(getattr(context, "space_data", None), "shading", None)
    return shading is not None and shading.type == "MATERIAL" and not shading.use_scene_world


def _draw_render_settings(layout, context) -> None:
    """Splats in Renders, and what F12 will contain (render/setup.py), with the last render's messages."""
    from ..render import frame as render_frame
    from ..render import setup as render_setup
    scene = context.scene
    rs = getattr(scene, "gs_ibl_render", None)
    if rs is None:
        return
    # One setting a row: side by side at the sidebar's default width they read "Splats i…", "Transpa…"
    col = layout.column(align=True)
    col.prop(rs, "enabled", icon="RESTRICT_RENDER_OFF" if rs.enabled else "RESTRICT_RENDER_ON")
    if rs.enabled:
        col.prop(rs, "write_pass", text="Pass", icon="FILE_IMAGE")
        if rs.write_pass:
            col.prop(rs, "pass_path", text="")
        col.prop(rs, "transparent", icon="WORLD")  # off: the World behind meshes and splats
        if hasattr(rs, "shadows"):
            col.prop(rs, "shadows", icon="LIGHT_SUN")
            if rs.shadows:
                col.prop(rs, "shadow_strength", slider=True)  # "Strength" alone read as the probe's
        if hasattr(rs, "native_splats") and any(is_native_splats(o) for o in scene.objects):  # Blender 5.3+
            col.label(text="Native Splats")
            col.row(align=True).prop(rs, "native_splats", expand=True)
    line, notes = render_setup.describe(scene, getattr(context, "view_layer", None))
    _label_block(col, context, line, icon="RENDER_STILL")
    for note in notes:
        _label_block(col, context, note)
    for message in render_frame.messages_now(scene):
        _label_block(col, context, f"Last render: {message}", icon="ERROR")


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
            box = layout.box()
            info = obj.get("gs_ibl")  # ours (mesh, or native on 5.3+) remember their file; Blender's importers don't
            text = f"{splat_count(obj):,} splats" + (f", SH {info.get('sh_degree', '?')}" if info else "")
            box.label(text=text + (" (Blender's Gaussian splats)" if is_native_splats(obj) else ""))
            if info:
                source = str(info.get("source", ""))
                box.label(text=os.path.basename(source) or source)  # the path would be cut; its file name fits
            box.prop(obj.gs_ibl_splats, "colour_space", text="Colours")
        ov = context.scene.gs_ibl_overlay
        row = layout.row(align=True)
        row.prop(ov, "show", toggle=True, icon="HIDE_OFF" if ov.show else "HIDE_ON")
        if ov.show:
            row.prop(ov, "resolution_scale", text="Resolution")  # without a label it read "0.50", unexplained
            layout.prop(ov, "exposure")
            from ..viewport import overlay
            if overlay.error_text():
                _label_block(layout.box(), context, f"Splats not drawn: {overlay.error_text()}", icon="ERROR")
        _draw_render_settings(layout, context)
        probe = find_probe(context)
        layout.operator(GSIBL_OT_add_probe.bl_idname, icon="LIGHTPROBE_SPHERE")
        if probe is None:
            return
        s = probe.gs_ibl_probe
        # No property split: at the sidebar's default width a split cuts labels such as "Use as Scene World";
        # sliders carry their name inside, checkboxes beside.
        col = layout.column()
        col.label(text=probe.name, icon="EMPTY_DATA")
        if probe.parent is not None:
            col.label(text=f"Follows {probe.parent.name} (its parent)", icon="LINKED")
        moving = animated_text(probe)
        if moving is not None:
            _label_block(col, context, moving[0].upper() + moving[1:], icon="ANIM")
        col.prop(s, "splats")
        own = s.splats if s.splats is not None and sources.in_scene(context.scene, s.splats) else None
        others = sources.lighting_set(context.scene, own)[1:] if own is not None else []
        if others:  # the bake reads them too (every splat object shown in renders)
            _label_block(col, context, "With " + ", ".join(o.name for o in others[:4])
                         + (", ..." if len(others) > 4 else "") + " (shown in renders)", icon="LINKED")
        col.prop(s, "lighting")
        if s.lighting == "VOLUME":
            col.prop(s, "volume_probes")
        if s.splats is not None and not sources.in_scene(context.scene, s.splats):
            _label_block(col, context, f"{s.splats.name} is not in this scene: pick another", icon="ERROR")
        col.prop(s, "method")
        col.prop(s, "face_size")
        col.prop(s, "irradiance_size")
        col.prop(s, "tolerance")
        col.prop(s, "highlight_gain")
        col.prop(s, "lights")
        col.prop(s, "strength")
        col.prop(s, "keep_background")
        col.prop(s, "assign_world")
        if s.assign_world and gw.native_splats_in(context.scene):
            # shown only where it matters: the scene renders Blender 5.3 native splats, whose bounce light Cycles
            # would add to the same light in our World
            col.prop(s, "mute_native_splats")
        col.prop(s, "pack_images")
        col.prop(s, "auto_update")
        if s.auto_update:
            col.prop(s, "update_interval")
        layout.operator(GSIBL_OT_bake_probe.bl_idname, text="Bake / Refresh", icon="RENDER_STILL")
        for runner in running():  # also in the status bar; here beside the button that started it
            _label_block(layout.box(), context, runner.status(), icon="TIME")
        if s.last_report:
            col = layout.box().column(align=True)
            reasons = stale_reasons(context.scene, probe)
            if reasons:  # the probe, its splats or a lit mesh moved since, or an undo brought back an older report
                _label_block(col, context, stale_text(reasons), icon="ERROR")
            lines = s.last_report.split("\n")
            warnings = [line for line in lines if line.startswith(gb.WARNING_PREFIX)]
            # one line (time, face size, error, lighting) and the warnings; the whole report one click away
            first = next((line for line in lines if line not in warnings), "")  # a file baked before the summary
            if s.last_summary or first:
                _label_block(col, context, s.last_summary or first, icon="INFO")
            for line in warnings:
                _label_block(col, context, line, icon="ERROR")
            wm = context.window_manager
            details = bool(getattr(wm, "gs_ibl_report_details", False))
            col.prop(wm, "gs_ibl_report_details", text="Details", emboss=False,
                     icon="DISCLOSURE_TRI_DOWN" if details else "DISCLOSURE_TRI_RIGHT")
            if details:
                for line in lines:
                    if not line.startswith(gb.WARNING_PREFIX):
                        _label_block(col, context, line)
            stale = stale_images(probe)
            if stale:  # undo brought back an earlier bake's World, but its image files hold the later bake
                _label_block(col, context, f"{gb.WARNING_PREFIX}the image files ({', '.join(stale)}) hold a later "
                             "bake than this report (undo cannot restore files): Bake / Refresh", icon="ERROR")
        if s.world is not None and scene_world_hidden(context):
            _label_block(layout.box(), context, "Material Preview shows the baked light only with Scene World on "
                         "(Viewport Shading popover), or in Rendered mode", icon="INFO")
        if isinstance(context.scene.get(gw.PREVIOUS_WORLD), bpy.types.World):
            layout.operator(GSIBL_OT_restore_world.bl_idname, icon="LOOP_BACK")


class GSIBL_PT_render_settings(bpy.types.Panel):
    """The render settings also where Blender's own are: Properties editor > Render (the same draw as the
    sidebar's)."""
    bl_label = "GS-IBL Splats"
    bl_idname = "GSIBL_PT_render_settings"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"

    def draw(self, context):
        _draw_render_settings(self.layout, context)


def menu_add(self, context):
    self.layout.operator(GSIBL_OT_add_probe.bl_idname, text="GS-IBL Probe", icon="LIGHTPROBE_SPHERE")


CLASSES = (GSIBL_OT_add_probe, GSIBL_OT_bake_probe, GSIBL_OT_restore_world, GSIBL_PT_panel, GSIBL_PT_render_settings)
MENUS = ((bpy.types.VIEW3D_MT_add, menu_add),)
