"""Lighting Auto (blender/lighting/auto_light.py, core/probe/auto_light.py): in the sample room, a small mesh by the World
probe keeps the World's light, one far from it gets a probe of its own, a large one spanning the room's light a
grid; each mesh's numbers are the batched probes' minus the World's; moving a lit mesh chooses its light again.
The choices print their offsets and variations (pytest -s)."""
from __future__ import annotations

import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLE = os.path.join(ROOT, "samples", "room.ply")


def _mesh(kind: str, location, size: float):
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    if kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=size, location=location, segments=16, ring_count=8)
    else:
        bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    return bpy.context.active_object


@pytest.fixture
def room(blender):
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=SAMPLE, show_proxy=False) == {"FINISHED"}
    splats = bpy.context.active_object
    near = _mesh("sphere", (0.0, 0.0, 1.0), 0.05)  # at the probe: the World's light is its light
    far = _mesh("sphere", (-2.2, -1.8, 0.6), 0.02)  # the far corner, tiny: light of its own, uniform across it
    big = _mesh("cube", (0.0, 0.0, 1.4), 2.4)  # the middle of the room, lamp to window: the light changes across it
    for o in bpy.context.view_layer.objects.selected:
        o.select_set(False)
    bpy.context.scene.cursor.location = (0.0, 0.0, 1.0)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 32, 8
    return splats, probe, {"near": near, "far": far, "big": big}


def test_each_mesh_gets_the_light_it_needs(room, tmp_path):
    from gs_ibl_addon.blender.lighting import local_light as ll
    from gs_ibl_addon.core.probe.grid import bake_sh_points, monomial_coefficients
    from gs_ibl_addon.blender.splats import cache as splat_cache
    from gs_ibl_addon.blender.lighting import auto_update as au
    splats, probe, meshes = room
    assert probe.gs_ibl_probe.lighting == "AUTO"  # the default
    probe.gs_ibl_probe.auto_update = True
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    print(probe.gs_ibl_probe.local_report)
    kinds = {k: ll.has_local_light(o) for k, o in meshes.items()}
    assert kinds == {"near": None, "far": "probe", "big": "grid"}, kinds
    assert "Auto lighting: 3 meshes: 1 by the World probe, 1 with a probe of their own, 1 with a grid" in \
        probe.gs_ibl_probe.last_report
    # the far sphere's numbers: a probe at its centre minus the World probe's, baked the same way
    r = splat_cache.get(splats).renderer
    pts = np.array([probe.matrix_world.translation, meshes["far"].matrix_world.translation], np.float64)
    d = monomial_coefficients(bake_sh_points(r, pts))
    img, tiles = ll._atlas()
    tile = tiles[f"probe:{meshes['far'].name}"]
    got = ll._tile_pixels(img, tile)
    from gs_ibl_addon.core.probe.grid import pack_grid
    want = pack_grid((d[1] - d[0]).reshape(1, 1, 1, 9, 3).astype(np.float32))
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)
    # moving a lit mesh chooses its light again; the World is not baked again
    bakes, relights = au.auto_bakes, au.auto_relights
    meshes["near"].location = (-2.2, -1.8, 1.0)  # to the far corner
    bpy.context.view_layer.update()
    assert (bpy.context.scene.name, probe.name) in au._pending_meshes
    bpy.app.timers.unregister(au.run_pending)  # timers run only in Blender's event loop: run it as Blender would
    au.run_pending()
    assert au.auto_bakes == bakes and au.auto_relights == relights + 1
    assert ll.has_local_light(meshes["near"]) is not None
    meshes["near"].location = (0.0, 0.0, 1.0)  # back by the probe: the World's light again
    bpy.context.view_layer.update()
    bpy.app.timers.unregister(au.run_pending)
    au.run_pending()
    assert ll.has_local_light(meshes["near"]) is None
    # saved and reopened: a lit mesh moved is relit, the World not baked again
    path, probe_name, names = str(tmp_path / "auto.blend"), probe.name, {k: o.name for k, o in meshes.items()}
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    probe, meshes = scene.objects[probe_name], {k: scene.objects[n] for k, n in names.items()}
    bakes, relights = au.auto_bakes, au.auto_relights
    meshes["near"].location = (-2.2, -1.8, 1.0)
    bpy.context.view_layer.update()
    assert (scene.name, probe.name) in au._pending_meshes
    bpy.app.timers.unregister(au.run_pending)
    au.run_pending()
    assert au.auto_bakes == bakes and au.auto_relights == relights + 1
    assert ll.has_local_light(meshes["near"]) is not None
    assert "Auto lighting after the last move: 1 mesh: " in probe.gs_ibl_probe.last_report  # Details says it
    assert "; after a move: 1 mesh relit in " in probe.gs_ibl_probe.last_summary  # and the panel's line
    # noted again while that relight ran (a drag paused, then ended): it stands where it was relit, nothing to do
    au._pending_meshes[(scene.name, probe.name)] = {meshes["near"].name}
    au.run_pending()
    assert au.auto_relights == relights + 1
    # World Probe takes Auto's light off again (what the operators gave stays: test_blender_probes.py)
    probe.gs_ibl_probe.lighting = "WORLD"
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert all(ll.has_local_light(o) is None for o in meshes.values())


def test_world_probe_lighting_adds_nothing(room):
    from gs_ibl_addon.blender.lighting import local_light as ll
    _splats, probe, meshes = room
    probe.gs_ibl_probe.lighting = "WORLD"
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert all(ll.has_local_light(o) is None for o in meshes.values())
    assert "Auto lighting" not in probe.gs_ibl_probe.last_report
