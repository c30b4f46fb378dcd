"""The render settings in the GS-IBL panel, found by a real-GUI check in Blender 5.2.2 (sidebar at its default
width): labels cut where settings shared a row, two fields named "Strength", a last render's message a later bake
made untrue, the stale mark beside a running bake's progress, Lighting changes not marking the bake, an animated
parent not said, and the settings in the Properties editor's Render tab."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")

from tests.panel_recorder import Rows, draw_panel  # noqa: E402

RENDER_PROPS = ("enabled", "write_pass", "transparent", "shadows", "shadow_strength")


def _render_settings_on():
    rs = bpy.context.scene.gs_ibl_render
    rs.enabled, rs.write_pass, rs.shadows = True, True, True
    return rs


def test_every_render_setting_has_a_row_of_its_own(blender):
    """Side by side at the sidebar's default width the labels read "Splats i…", "Transpa…", "Shadows on Sp…"."""
    _render_settings_on()
    rec = draw_panel()
    shown = [name for name, _ in rec["props"]]
    for name in RENDER_PROPS:
        assert name in shown, name
    for row in rec["containers"]:
        together = [n for n in row if n in RENDER_PROPS]
        assert len(together) <= 1, f"{together} share a row: their labels are cut at the sidebar's width"


def test_no_two_fields_share_a_name(blender):
    """The shadow strength read "Strength", like the probe's strength below it."""
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    _render_settings_on()
    rec = draw_panel()
    texts = [text for _, text in rec["props"] if text]
    assert ("shadow_strength", "Shadow Strength") in rec["props"]
    assert ("strength", "Strength") in rec["props"]
    assert len(texts) == len(set(texts)), sorted(t for t in texts if texts.count(t) > 1)
    # the identifier stays: files saved before keep their value
    assert bpy.context.scene.gs_ibl_render.bl_rna.properties["shadow_strength"].name == "Shadow Strength"


def test_a_bake_drops_the_last_renders_no_probe_world_message(blender, tmp_path, write_3dgs_ply):
    """"Last render: no shadows on the splats: the scene's World is not a baked probe's" stayed under the report of
    the bake that since made the World a probe's. Other messages of that render stay."""
    from tests.test_blender_panel import _import, _probe
    from gs_ibl_addon.blender.render import frame
    scene = bpy.context.scene
    _render_settings_on()
    _import(tmp_path, write_3dgs_ply)
    probe = _probe(place="CURSOR", lighting="WORLD")
    _, why = frame.probe_light(scene)  # what an F12 render says now, before a bake
    assert why is not None and why.startswith(frame.NO_PROBE_WORLD)
    other = "splats not drawn: the scene has no camera (Scene Properties > Camera)"
    frame._last[scene.name] = {"messages": [other, why], "frames": {}, "cancelled": False}

    def shown() -> str:  # the panel's labels, wrapped lines joined again
        return " ".join(t for t, _ in draw_panel()["labels"])

    assert f"Last render: {frame.NO_PROBE_WORLD}" in shown()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert probe.gs_ibl_probe.world is scene.world and frame.probe_light(scene)[1] is None
    assert frame.NO_PROBE_WORLD not in shown()
    assert f"Last render: {other}" in shown()
    frame._last.pop(scene.name, None)


def test_a_running_bake_is_not_marked_out_of_date(blender, tmp_path, write_3dgs_ply):
    """The status bar showed the bake's progress and "the bake of 'GS-IBL Probe' is out of date (the probe moved)"
    side by side, the mark about the very bake that was making it good."""
    from tests.test_blender_panel import _import, _probe
    from gs_ibl_addon.blender.common.jobs import notices
    from gs_ibl_addon.blender.lighting import bake as gb
    from gs_ibl_addon.blender.lighting.stale import refresh_notice, stale_reasons
    scene = bpy.context.scene
    splats = _import(tmp_path, write_3dgs_ply)
    probe = _probe(place="CURSOR", lighting="WORLD")
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    probe.location.x += 0.5

    def marked() -> bool:
        bpy.context.view_layer.update()  # the probe's matrix_world follows its location
        refresh_notice(scene)
        in_bar = any("out of date" in n and repr(probe.name) in n for n in notices())
        in_panel = any(t.startswith("Out of date") for t, _ in draw_panel()["labels"])
        assert in_bar == in_panel == bool(stale_reasons(scene, probe))
        return in_bar

    assert marked()
    job = gb.bake_job(scene, probe, splats)
    next(job)  # its first step: the bake runs (a Runner drives it between redraws)
    assert not marked()
    job.close()  # cancelled: the old bake is still out of date
    assert marked()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert not marked()


def test_switching_lighting_marks_the_bake_out_of_date(blender, tmp_path, write_3dgs_ply):
    """Auto / Volume / World Probe light meshes differently: after a switch the bake no longer says how they are
    lit. Undo brings the Lighting back with the bake's record (both on the probe): no mark; a re-bake clears it."""
    from tests.test_blender_panel import _import, _probe
    from gs_ibl_addon.blender.common.jobs import notices
    from gs_ibl_addon.blender.lighting.stale import stale_reasons
    _import(tmp_path, write_3dgs_ply)
    probe = _probe(place="CURSOR", lighting="WORLD")
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="bake")
    name = probe.name

    def reasons() -> list[str]:
        bpy.context.view_layer.update()  # the depsgraph update whose handler refreshes the status bar
        probe = bpy.data.objects[name]
        out = stale_reasons(bpy.context.scene, probe)  # undo replaced the scene and probe datablocks
        in_bar = any("out of date" in n and "Lighting" in n for n in notices())
        assert in_bar == any("Lighting" in r for r in out), (notices(), out)
        return out

    assert reasons() == []
    probe.gs_ibl_probe.lighting = "AUTO"
    bpy.ops.ed.undo_push(message="lighting")
    assert reasons() == ["its Lighting is now Auto"]
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert bpy.data.objects[name].gs_ibl_probe.lighting == "WORLD" and reasons() == []
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert reasons() == ["its Lighting is now Auto"]
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert reasons() == []


def test_an_animated_parent_is_said(blender, tmp_path, write_3dgs_ply):
    """Add Probe parents the probe to the selected mesh; when that mesh is animated the World is baked where it
    stands at the current frame, which the panel and the report did not say."""
    from tests.test_blender_panel import _import
    scene = bpy.context.scene
    _import(tmp_path, write_3dgs_ply)
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(0.5, 0.0, 0.0))
    cube = bpy.context.active_object
    cube.name = "MovingCube"
    bpy.ops.gs_ibl.add_probe(place="SELECTED")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 16, 8
    probe.gs_ibl_probe.lighting = "WORLD"
    assert probe.parent is cube

    def labels() -> str:
        return " ".join(t for t, _ in draw_panel()["labels"])

    assert "Follows MovingCube" in labels() and "animated" not in labels()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert "animated" not in probe.gs_ibl_probe.last_report
    cube.keyframe_insert("location", frame=1)
    cube.location.x = 1.0
    cube.keyframe_insert("location", frame=10)
    scene.frame_set(4)
    assert "The probe follows MovingCube, which is animated" in labels()
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert "the probe follows MovingCube, which is animated: baked at frame 4" in probe.gs_ibl_probe.last_report
    scene.frame_set(1)


def test_the_render_tab_shows_the_same_settings(blender, monkeypatch):
    """Properties editor > Render has a GS-IBL Splats panel: the sidebar's render settings, drawn by the same
    function (not a copy that could drift)."""
    from gs_ibl_addon.blender.ui import panel
    cls = bpy.types.Panel.bl_rna_get_subclass_py("GSIBL_PT_render_settings")
    assert cls is not None, "not registered"
    assert (cls.bl_space_type, cls.bl_region_type, cls.bl_context) == ("PROPERTIES", "WINDOW", "render")
    _render_settings_on()
    rec: dict = {}
    cls.draw(SimpleNamespace(layout=Rows(rec)), bpy.context)
    sidebar = [p for p in draw_panel()["props"] if p[0] in RENDER_PROPS + ("pass_path", "native_splats")]
    assert rec["props"] == sidebar and {name for name, _ in sidebar} >= set(RENDER_PROPS)
    calls = []
    monkeypatch.setattr(panel, "_draw_render_settings", lambda layout, context: calls.append(layout))
    cls.draw(SimpleNamespace(layout="render tab"), bpy.context)
    panel.GSIBL_PT_panel.draw(SimpleNamespace(layout=Rows({})), bpy.context)
    assert calls[0] == "render tab" and len(calls) == 2
