"""Operators and the sidebar sub-panel for more than one probe: Check Light Variation, Per-Object Probes,
Probe Grid, Remove Local Light. They act on the selected meshes, else on every mesh inside the splats' bounds."""
from __future__ import annotations

import bpy

from ..lighting import object_probes as op
from ..lighting import probe_grid as pgrid
from .panel import _label_block, find_probe


def _progress(context, what: str):
    wm = context.window_manager
    wm.progress_begin(0, 100)

    def say(done: int, total: int) -> None:
        wm.progress_update(int(100 * done / max(total, 1)))
        if bpy.app.background:
            print(f"GS-IBL: {what} probe {done} of {total}")
    return say


def _run(operator, context, fn):
    """Run ``fn(scene, probe, meshes, progress)`` and report its lines; core and Blender errors become one line."""
    probe = find_probe(context)
    meshes = op.lit_meshes(context.scene, probe, context.selected_objects)
    try:
        out = fn(context.scene, probe, meshes, _progress(context, operator.bl_label))
    except (ValueError, RuntimeError, OSError, MemoryError) as e:
        operator.report({"ERROR"}, str(e))
        return {"CANCELLED"}
    finally:
        context.window_manager.progress_end()
    return out


class GSIBL_OT_check_variation(bpy.types.Operator):
    """Bake cheap probes at each mesh's bounding-box corners and say where one probe is not enough"""
    bl_idname = "gs_ibl.check_variation"
    bl_label = "Check Light Variation"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def execute(self, context):
        out = _run(self, context, op.check_variation)
        if isinstance(out, set):
            return out
        found, lines = out
        tol = find_probe(context).gs_ibl_probe.variation_tolerance
        self.report({"WARNING"} if any(v.exceeds(tol) for v in found) else {"INFO"}, "; ".join(lines))
        return {"FINISHED"}


class GSIBL_OT_object_probes(bpy.types.Operator):
    """Give each mesh its own probe at its centre (through its materials; the World stays)"""
    bl_idname = "gs_ibl.object_probes"
    bl_label = "Per-Object Probes"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def execute(self, context):
        out = _run(self, context, op.bake_object_probes)
        if isinstance(out, set):
            return out
        self.report({"INFO"}, out)
        return {"FINISHED"}


class GSIBL_OT_probe_grid(bpy.types.Operator):
    """Bake a grid of probes over the Grid Region and light the meshes by interpolating it"""
    bl_idname = "gs_ibl.probe_grid"
    bl_label = "Probe Grid"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def execute(self, context):
        out = _run(self, context, pgrid.bake_probe_grid)
        if isinstance(out, set):
            return out
        self.report({"INFO"}, out[0])
        return {"FINISHED"}


class GSIBL_OT_remove_local_light(bpy.types.Operator):
    """Take per-object probes and the grid off the selected meshes (all, when none is selected)"""
    bl_idname = "gs_ibl.remove_local_light"
    bl_label = "Remove Local Light"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        n = op.remove_local_light(context.scene, [o for o in context.selected_objects if o.type == "MESH"])
        self.report({"INFO"}, f"Local light removed from {n} objects")
        return {"FINISHED"}


class GSIBL_PT_local_light(bpy.types.Panel):
    bl_label = "More Than One Probe"
    bl_idname = "GSIBL_PT_local_light"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "GS-IBL"
    bl_parent_id = "GSIBL_PT_panel"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return find_probe(context) is not None

    def draw(self, context):
        layout = self.layout
        s = find_probe(context).gs_ibl_probe
        col = layout.column()
        col.prop(s, "variation_tolerance")
        col.operator(GSIBL_OT_check_variation.bl_idname, icon="LIGHTPROBE_VOLUME")
        col.operator(GSIBL_OT_object_probes.bl_idname, icon="LIGHTPROBE_SPHERE")
        col.prop(s, "grid_region")
        col.prop(s, "grid_resolution")
        col.operator(GSIBL_OT_probe_grid.bl_idname, icon="LIGHTPROBE_VOLUME")
        col.operator(GSIBL_OT_remove_local_light.bl_idname, icon="X")
        if s.local_report:
            box = layout.box().column(align=True)
            for line in s.local_report.split("\n"):
                _label_block(box, context, line, icon="ERROR" if "use a per-object probe" in line else "NONE")


CLASSES = (GSIBL_OT_check_variation, GSIBL_OT_object_probes, GSIBL_OT_probe_grid, GSIBL_OT_remove_local_light,
           GSIBL_PT_local_light)
