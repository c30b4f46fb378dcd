"""A .blend saved by an earlier version opens and bakes: property, operator and node-group names are the file's
interface, whatever the modules behind them are called."""
from __future__ import annotations

import os
import shutil

import pytest

DATA = os.path.join(os.path.dirname(__file__), "data", "before_rooms.blend")


def test_file_from_before_the_rooms_opens_and_bakes(blender, tmp_path):
    bpy = blender
    from gs_ibl_addon.blender.common.datablocks import is_ours, is_probe
    from gs_ibl_addon.blender.lighting import local_light as ll
    path = tmp_path / "before_rooms.blend"
    shutil.copy(DATA, path)  # Blender may write next to the file it opened
    bpy.ops.wm.open_mainfile(filepath=str(path))
    probe = next(o for o in bpy.data.objects if is_probe(o))
    s = probe.gs_ibl_probe
    assert s.splats is not None and s.splats.name == "Room"
    assert s.strength == pytest.approx(1.5) and s.face_size == 16
    assert is_ours(s.world, "world") and bpy.context.scene.world == s.world
    ball = bpy.data.objects["Ball"]
    assert ll.has_local_light(ball)  # the Auto light the old version gave it is recognised as ours
    old_report = s.last_report
    s.lighting = "WORLD"  # the quick bake: the World alone, and the old local light taken off
    from gs_ibl_addon.blender.lighting.bake import bake_into_world
    result, text, _warning = bake_into_world(bpy.context.scene, probe)
    assert result.splat_count == 1068 and s.last_report != old_report
    assert not ll.has_local_light(ball)
    assert s.world.node_tree is not None and is_ours(s.world, "world")
