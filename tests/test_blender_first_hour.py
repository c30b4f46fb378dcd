"""What a new user hits in the first hour (issue 21), in the bpy module: a deleted splat object is never baked, two
splat objects get the right message, splats show after import, a probe follows the mesh it was placed at, and undo
or redo brings back the World's light with its report and re-bakes nothing."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gs_ibl_addon.core.synthetic import SkyGradient, shell_scene  # noqa: E402

SKY = SkyGradient()


def _import(tmp_path, write_3dgs_ply, name="shell", n=3000, radius=5.0, center=(0.0, 0.0, 0.0), **kw):
    path = tmp_path / f"{name}.ply"
    write_3dgs_ply(path, shell_scene(SKY, n, radius, center))
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), axis_preset="BLENDER", show_proxy=False, **kw) \
        == {"FINISHED"}
    obj = bpy.context.active_object
    obj.gs_ibl_splats.colour_space = "LINEAR"
    return obj


def _small(probe) -> None:
    s = probe.gs_ibl_probe
    s.face_size, s.irradiance_size = 16, 8


def _radiance(probe) -> np.ndarray:
    from gs_ibl_addon.blender.lighting import world as gw
    return gw.image_latlong_pixels(probe.gs_ibl_probe.radiance_image)


def _delete(obj) -> None:
    """What the viewport's Delete does: the object leaves the scene; a pointer to it keeps it in bpy.data."""
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.object.delete() == {"FINISHED"}


def test_a_deleted_splat_object_is_never_baked(blender, tmp_path, write_3dgs_ply):
    from gs_ibl_addon.blender.lighting import auto_update as au
    splats = _import(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    _small(probe)
    probe.gs_ibl_probe.auto_update = True
    assert probe.gs_ibl_probe.splats == splats
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    world = bpy.context.scene.world
    name = splats.name
    _delete(splats)
    bpy.context.view_layer.update()
    assert not au._pending and not bpy.app.timers.is_registered(au.run_pending)  # the delete starts no re-bake
    assert probe.gs_ibl_probe.splats is None  # its object left every scene: the field is cleared
    bpy.context.view_layer.objects.active = probe
    with pytest.raises(RuntimeError, match="No splat object in the scene"):
        bpy.ops.gs_ibl.bake_probe()
    assert bpy.context.scene.world == world
    # moved to another scene: the field keeps it (it is still somewhere), and this scene's bake refuses it by name
    again = _import(tmp_path, write_3dgs_ply, name="again")
    probe.gs_ibl_probe.splats = again
    bpy.data.scenes.new("Other").collection.objects.link(again)
    bpy.context.scene.collection.objects.unlink(again)
    bpy.context.view_layer.objects.active = probe
    with pytest.raises(RuntimeError, match=r"'again' is no longer in the scene \(deleted or unlinked\)"):
        bpy.ops.gs_ibl.bake_probe()
    assert name not in bpy.context.scene.objects


def test_two_splat_objects_ask_which(blender, tmp_path, write_3dgs_ply):
    from gs_ibl_addon.blender.lighting.sources import enclosing_splats
    room = _import(tmp_path, write_3dgs_ply, name="room", radius=5.0)
    small = _import(tmp_path, write_3dgs_ply, name="small", n=500, radius=0.5, center=(2.0, 0.0, 0.0))
    # a probe inside the room (and inside the small capture's bounds too) takes the room: the one it stands in
    assert enclosing_splats(bpy.context.scene, (2.0, 0.0, 0.0)) == room
    assert enclosing_splats(bpy.context.scene, (50.0, 0.0, 0.0)) is None
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.2, location=(0.5, 0.5, 0.0))
    bpy.ops.gs_ibl.add_probe()
    probe = bpy.context.active_object
    assert probe.gs_ibl_probe.splats == room
    probe.gs_ibl_probe.splats = None  # the field left empty with two candidates: the bake asks which
    with pytest.raises(RuntimeError, match=r"2 splat objects in the scene \('room', 'small'\): pick one"):
        bpy.ops.gs_ibl.bake_probe()
    probe.gs_ibl_probe.splats = small
    _small(probe)
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}


def test_splats_are_shown_after_import(blender, tmp_path, write_3dgs_ply):
    ov = bpy.context.scene.gs_ibl_overlay
    assert not ov.show
    _import(tmp_path, write_3dgs_ply, name="quiet", show_splats=False)
    assert not ov.show
    _import(tmp_path, write_3dgs_ply)
    assert ov.show  # drawn at once, not a grey pin-cushion of proxy points


def test_import_button_label_fits():
    # the file browser's button shows the label; "Import Gaussian Splatting" was cut to "Import Gaussian Spl..."
    from gs_ibl_addon.blender.splats.importer import GSIBL_OT_import_splats
    assert len(GSIBL_OT_import_splats.bl_label) <= 14


def test_probe_follows_the_mesh_it_was_placed_at(blender, tmp_path, write_3dgs_ply):
    from gs_ibl_addon.blender.lighting import auto_update as au
    _import(tmp_path, write_3dgs_ply)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(1.0, -0.5, 0.2))
    sphere = bpy.context.active_object
    bpy.ops.gs_ibl.add_probe()
    probe = bpy.context.active_object
    assert probe.parent == sphere
    np.testing.assert_allclose(probe.matrix_world.translation, (1.0, -0.5, 0.2), atol=1e-6)
    _small(probe)
    probe.gs_ibl_probe.auto_update = True
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    sphere.location = (0.0, 1.5, 1.0)  # moving the lit mesh moves its probe, and Update When Moved re-bakes
    bpy.context.view_layer.update()
    np.testing.assert_allclose(probe.matrix_world.translation, (0.0, 1.5, 1.0), atol=1e-6)
    assert au._pending == {(bpy.context.scene.name, probe.name)}
    bpy.app.timers.unregister(au.run_pending)  # timers run only in Blender's event loop: run it as Blender would
    before = au.auto_bakes
    au.run_pending()
    assert au.auto_bakes == before + 1 and au.last_auto_error is None
    # placed at the cursor, or with Follow Mesh off, a probe has no parent
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    assert bpy.context.active_object.parent is None
    sphere.select_set(True)
    bpy.context.view_layer.objects.active = sphere
    bpy.ops.gs_ibl.add_probe(follow=False)
    assert bpy.context.active_object.parent is None


def test_undo_and_redo_bring_back_the_light_with_its_report_and_bake_nothing(blender, tmp_path, write_3dgs_ply):
    from gs_ibl_addon.blender.lighting import auto_update as au
    _import(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe_name = bpy.context.active_object.name
    probe = bpy.data.objects[probe_name]
    _small(probe)
    probe.gs_ibl_probe.auto_update = True
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    first = (_radiance(probe), probe.gs_ibl_probe.last_report)
    bpy.ops.ed.undo_push(message="bake 1")
    probe.location = (0.0, 0.0, 3.5)  # moved (the view of the sky gradient changes) and baked again
    bpy.context.view_layer.update()
    bpy.app.timers.unregister(au.run_pending)
    au.run_pending()
    probe = bpy.data.objects[probe_name]
    second = (_radiance(probe), probe.gs_ibl_probe.last_report)
    assert not np.allclose(first[0], second[0], rtol=0.01)
    bpy.ops.ed.undo_push(message="bake 2")
    before = au.auto_bakes
    for step, want in ((bpy.ops.ed.undo, first), (bpy.ops.ed.redo, second), (bpy.ops.ed.undo, first)):
        assert step() == {"FINISHED"}
        bpy.context.view_layer.update()  # the depsgraph update that once scheduled a re-bake
        probe = bpy.data.objects[probe_name]
        assert not au._pending and not bpy.app.timers.is_registered(au.run_pending)
        np.testing.assert_array_equal(_radiance(probe), want[0])  # the World shows the light its report describes
        assert probe.gs_ibl_probe.last_report == want[1]
    assert au.auto_bakes == before
