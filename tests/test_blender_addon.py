"""The extension inside Blender (bpy module): register/unregister, import, splat object, World writing, probes."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import gs_ibl_addon  # noqa: E402
from gs_ibl_addon.core.scene import sh_dc_to_rgb  # noqa: E402
from gs_ibl_addon.core.synthetic import random_scene  # noqa: E402
from gs_ibl_addon.core.image_io import read_exr  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# ---------------------------------------------------------------------------------------------- package

def test_package_imports_without_bpy():
    """`import gs_ibl_addon` must work in a plain Python where bpy does not exist (the CLI, CI without Blender)."""
    code = ("import sys; sys.modules['bpy'] = None; import gs_ibl_addon, gs_ibl_addon.core.scene; "
            "assert callable(gs_ibl_addon.register); print('ok')")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "ok" in r.stdout, r.stderr


def _draw_funcs(menu):
    return list(getattr(menu.draw, "_draw_funcs", []))


def test_register_unregister_leaves_nothing_behind():
    from gs_ibl_addon.blender import registration
    bpy.ops.wm.read_factory_settings(use_empty=True)
    handlers_before = {k: len(getattr(bpy.app.handlers, k)) for k in dir(bpy.app.handlers)
                       if isinstance(getattr(bpy.app.handlers, k), list)}
    menus = (bpy.types.TOPBAR_MT_file_import, bpy.types.VIEW3D_MT_add)
    menus_before = [_draw_funcs(m) for m in menus]
    from gs_ibl_addon.blender.lighting import auto_update
    from gs_ibl_addon.blender.viewport import overlay
    for _ in range(2):  # twice: a second register after unregister must work too
        gs_ibl_addon.register()
        assert all(cls.is_registered for cls in registration._CLASSES)
        assert auto_update.on_depsgraph_update in bpy.app.handlers.depsgraph_update_post
        assert overlay._handle is not None and hasattr(bpy.types.Scene, "gs_ibl_overlay")
        assert _op_exists("gs_ibl.import_splats") and _op_exists("gs_ibl.bake_probe")
        assert hasattr(bpy.types.Object, "gs_ibl_probe")
        assert len(_draw_funcs(bpy.types.TOPBAR_MT_file_import)) == len(menus_before[0]) + 1
        gs_ibl_addon.unregister()
    assert not any(cls.is_registered for cls in registration._CLASSES)
    for idname in ("import_splats", "add_probe", "bake_probe", "restore_world"):
        assert not _op_exists("gs_ibl." + idname), idname
    for name in ("GSIBL_FH_splats", "GSIBL_PT_panel", "GSIBL_ProbeSettings", "GSIBL_OverlaySettings"):
        assert not hasattr(bpy.types, name), name
    assert not hasattr(bpy.types.Object, "gs_ibl_probe") and not hasattr(bpy.types.Scene, "gs_ibl_overlay")
    assert auto_update.on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post
    assert not bpy.app.timers.is_registered(auto_update.run_pending)
    assert overlay._handle is None  # draw_handler_remove was called with the handle draw_handler_add gave
    for m in menus:  # Blender may keep its own draw wrapper; none of ours may remain
        assert not [f for f in _draw_funcs(m) if f.__module__.startswith("gs_ibl_addon")]
    assert len(_draw_funcs(menus[0])) == len(menus_before[0])
    handlers_after = {k: len(getattr(bpy.app.handlers, k)) for k in handlers_before}
    assert handlers_after == handlers_before


def _op_exists(idname: str) -> bool:
    mod, name = idname.split(".")
    try:
        getattr(getattr(bpy.ops, mod), name).get_rna_type()
        return True
    except (KeyError, AttributeError):
        return False


# ---------------------------------------------------------------------------------------------- import

def test_import_ply_creates_splat_object(blender, tmp_path, write_3dgs_ply):
    src = random_scene(500, sh_degree=2)
    path = tmp_path / "garden.ply"
    write_3dgs_ply(path, src)
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.name == "garden" and obj.select_get() and obj.name in bpy.context.scene.objects
    assert obj["gs_ibl"]["source"] == str(path) and obj["gs_ibl"]["sh_degree"] == 2
    assert len(obj.data.vertices) == 500 and not obj.hide_render  # in renders, drawn by blender/render/
    assert not obj.modifiers[0].show_render  # the point proxy never renders
    # default orientation (3DGS/OpenCV): the file's -Y is Blender's +Z, its +Z is Blender's +Y
    m = np.array(obj.matrix_world)
    np.testing.assert_allclose(m[:3, :3] @ [0, -1, 0], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(m[:3, :3] @ [0, 0, 1], [0, 1, 0], atol=1e-6)
    # the import turns Show Splats on, which hides the point proxy; off, the proxy draws the splats as points.
    # Either way two more points of radius 0 (drawn as nothing) hold the splats' bounds, which View Selected frames.
    assert bpy.context.scene.gs_ibl_overlay.show
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    geometry = ev.evaluated_geometry()  # kept: its point cloud lives as long as it does
    hidden = geometry.pointcloud
    assert len(hidden.points) == 2 and set(hidden.attributes["radius"].data[i].value for i in range(2)) == {0.0}
    bpy.context.scene.gs_ibl_overlay.show = False
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    assert len(ev.evaluated_geometry().pointcloud.points) == 500 + 2
    from gs_ibl_addon.blender.splats.object import scene_from_mesh
    back = scene_from_mesh(obj.data)
    np.testing.assert_allclose(back.positions, src.positions, atol=1e-6)
    np.testing.assert_allclose(back.scales, src.scales, rtol=1e-5)
    np.testing.assert_allclose(np.abs((back.rotations * src.rotations).sum(1)), 1.0, atol=1e-5)
    np.testing.assert_allclose(back.opacities, src.opacities, atol=1e-5)
    np.testing.assert_allclose(back.sh, src.sh, atol=1e-5)
    colour = np.empty(500 * 4, np.float32)
    obj.data.attributes["gs_color"].data.foreach_get("color", colour)
    np.testing.assert_allclose(colour.reshape(-1, 4)[:, :3], np.maximum(sh_dc_to_rgb(src.sh[:, 0]), 0), atol=1e-5)


def test_scene_from_object_applies_world_transform(blender):
    from gs_ibl_addon.blender.splats.object import create_splat_object, scene_from_object
    src = random_scene(50, sh_degree=1)
    obj = create_splat_object(bpy.context, src, "S")
    obj.location = (1.0, 2.0, 3.0)
    obj.rotation_euler = (0.3, -0.2, 1.1)
    obj.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    got = scene_from_object(obj)
    want = src.transformed(np.array(obj.matrix_world))
    np.testing.assert_allclose(got.positions, want.positions, atol=1e-5)
    np.testing.assert_allclose(got.scales, src.scales * 2.0, rtol=1e-5)
    np.testing.assert_allclose(np.abs((got.rotations * want.rotations).sum(1)), 1.0, atol=1e-5)
    m = np.array(obj.matrix_world)
    np.testing.assert_allclose(got.positions[0], (m @ [*src.positions[0], 1.0])[:3], atol=1e-5)


def test_custom_axes_and_scale(blender, tmp_path, write_3dgs_ply):
    path = tmp_path / "s.ply"
    write_3dgs_ply(path, random_scene(10, sh_degree=1))
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), axis_preset="BLENDER", global_scale=3.0) == {"FINISHED"}
    np.testing.assert_allclose(np.array(bpy.context.active_object.matrix_world), np.diag([3.0, 3.0, 3.0, 1.0]),
                               atol=1e-6)
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), axis_preset="CUSTOM", axis_forward="-Z",
                                        axis_up="Y") == {"FINISHED"}
    m = np.array(bpy.context.active_object.matrix_world)
    np.testing.assert_allclose(m[:3, :3] @ [0, 1, 0], [0, 0, 1], atol=1e-6)


def test_default_orientation_brings_the_sample_upright(blender, tmp_path, write_3dgs_ply):
    """The default preset (Auto) takes the axes a file declares, as the bundled sample (made Z up) does, and treats
    a file that declares none as 3DGS training output (OpenCV: y down, z forward)."""
    from gs_ibl_addon.blender.splats.importer import import_matrix
    from gs_ibl_addon.core.formats.axes import declared_axes
    sample = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "samples", "room.ply")
    assert declared_axes(sample) == ("Y", "Z")
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=sample, show_proxy=False) == {"FINISHED"}
    np.testing.assert_allclose(np.array(bpy.context.active_object.matrix_world), np.identity(4), atol=1e-6)
    plain = tmp_path / "capture.ply"
    write_3dgs_ply(plain, random_scene(10, sh_degree=0))
    assert declared_axes(plain) is None
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(plain), show_proxy=False) == {"FINISHED"}
    m = np.array(bpy.context.active_object.matrix_world)
    np.testing.assert_allclose(m, import_matrix("OPENCV", "Z", "-Y", 1.0), atol=1e-6)
    np.testing.assert_allclose(m[:3, :3] @ [0, -1, 0], [0, 0, 1], atol=1e-6)  # the file's -Y is up


@pytest.mark.parametrize("content, expect", [
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n", "f_dc_0"),
    (b"not a splat file at all", "not a splat file"),
])
def test_bad_file_reports_error_and_leaves_nothing(blender, tmp_path, content, expect):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    counts = (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.node_groups), len(bpy.data.materials))
    with pytest.raises(RuntimeError) as e:  # bpy.ops turns an ERROR report into RuntimeError in background mode
        bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path))
    msg = str(e.value)
    assert expect in msg and str(path) in msg and "Traceback" not in msg
    assert (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.node_groups), len(bpy.data.materials)) == counts


def test_truncated_ply_reports_error(blender, tmp_path, write_3dgs_ply):
    path = tmp_path / "cut.ply"
    write_3dgs_ply(path, random_scene(100, sh_degree=1))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(RuntimeError, match="cut.ply"):
        bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path))
    assert len(bpy.data.objects) == 0 and len(bpy.data.meshes) == 0


def test_file_handler_registered_for_splat_extensions(blender):
    from gs_ibl_addon.core.formats import EXTENSIONS
    fh = bpy.types.GSIBL_FH_splats
    assert fh.bl_import_operator == "gs_ibl.import_splats"
    assert set(fh.bl_file_extensions.split(";")) == set(EXTENSIONS) - {".json"}  # every file type but SOG's meta.json


# ---------------------------------------------------------------------------------------------- World

def test_world_never_overwrites_user_world_and_restores(blender):
    from gs_ibl_addon.blender.lighting import world as gw
    scene = bpy.context.scene
    user = bpy.data.worlds.new("GS-IBL World")  # a user's World that happens to carry our name
    user.color = (0.2, 0.3, 0.4)
    user_img = bpy.data.images.new("GS-IBL Radiance", 4, 2)
    scene.world = user
    rad = np.full((8, 16, 3), 0.5, np.float32)
    rad[0] = 2.0  # top row (+Z) bright
    img = gw.latlong_image("radiance", rad)
    assert img != user_img and img.is_float and img.packed_file is not None
    np.testing.assert_allclose(gw.image_latlong_pixels(img), rad)
    w = gw.build_world(img, strength=2.0, keep_background=True, background_from=user)
    assert w != user and user.name == "GS-IBL World" and w.name.startswith("GS-IBL World")
    gw.use_world(scene, w)
    assert scene.world == w
    nodes = w.node_tree.nodes
    assert nodes["GS-IBL Strength"].inputs["Strength"].default_value == 2.0
    mix = nodes["GS-IBL Keep Background"]
    assert mix.inputs["Fac"].links[0].from_socket.name == "Is Camera Ray"
    # a rebuild replaces our World in place: the scene follows, the user's World is untouched
    assert gw.build_world(img, replace=user) != user  # a World not ours is never replaced
    bpy.data.worlds.remove([x for x in bpy.data.worlds if x.get("gs_ibl") and x != w][0])
    w2 = gw.build_world(img, strength=1.0, keep_background=False, background_from=user, replace=w)
    assert scene.world == w2 and len([x for x in bpy.data.worlds if x.get("gs_ibl")]) == 1
    assert "GS-IBL Keep Background" not in w2.node_tree.nodes
    assert gw.restore_world(scene) and scene.world == user
    assert tuple(user.color) == pytest.approx((0.2, 0.3, 0.4))
    assert user_img.name == "GS-IBL Radiance" and user_img.size[:] == (4, 2)


def test_apply_probe_images_and_strength_update(blender):
    from gs_ibl_addon.blender.lighting import world as gw
    from gs_ibl_addon.blender.lighting.bake import apply_probe_images
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    assert probe.name == "GS-IBL Probe" and probe.gs_ibl_probe.is_probe
    rad = np.random.default_rng(1).uniform(0, 1, (16, 32, 3)).astype(np.float32)
    irr = np.full((8, 16, 3), 0.25, np.float32)
    w = apply_probe_images(bpy.context.scene, probe, rad, irr)
    assert bpy.context.scene.world == w
    group = bpy.data.node_groups["GS-IBL Irradiance"]
    np.testing.assert_allclose(gw.image_latlong_pixels(group.nodes["GS-IBL Irradiance Image"].image), irr)
    probe.gs_ibl_probe.strength = 3.5
    assert w.node_tree.nodes["GS-IBL Strength"].inputs["Strength"].default_value == pytest.approx(3.5)


def test_images_saved_next_to_blend_survive_reload(blender, tmp_path):
    from gs_ibl_addon.blender.lighting import world as gw
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    rad = np.linspace(0, 4, 8 * 16 * 3, dtype=np.float32).reshape(8, 16, 3)  # > 1: must stay float
    img = gw.latlong_image("radiance", rad, pack=False)
    gw.use_world(bpy.context.scene, gw.build_world(img))
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.open_mainfile(filepath=blend)
    img = bpy.context.scene.world.node_tree.nodes["GS-IBL Radiance"].image
    assert os.path.isfile(bpy.path.abspath(img.filepath))
    np.testing.assert_allclose(gw.image_latlong_pixels(img), rad, rtol=1e-6)


def test_unpacked_images_never_overwrite_a_file_not_ours(blender, tmp_path):
    """Pack Images off: the EXRs get names of ours (gs_ibl_<probe>_<role>.exr); a file of that name we did not
    write is left as it is and ours takes a suffix; a re-bake rewrites our own files in place."""
    from gs_ibl_addon.blender.lighting import world as gw
    from gs_ibl_addon.blender.lighting.bake import apply_probe_images
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.pack_images = False
    theirs = tmp_path / "gs_ibl_GS-IBL_Probe_radiance.exr"
    theirs.write_bytes(b"the user's own file")
    rad = np.linspace(0, 3, 8 * 16 * 3, dtype=np.float32).reshape(8, 16, 3)
    irr = np.full((4, 8, 3), 0.25, np.float32)
    for k in (1.0, 2.0):  # bake, then re-bake
        apply_probe_images(bpy.context.scene, probe, k * rad, irr)
        s = probe.gs_ibl_probe
        assert theirs.read_bytes() == b"the user's own file"
        assert os.path.basename(s.radiance_image.filepath) == "gs_ibl_GS-IBL_Probe_radiance_1.exr"
        assert os.path.basename(s.irradiance_image.filepath) == "gs_ibl_GS-IBL_Probe_irradiance.exr"
        assert sorted(os.listdir(tmp_path)) == ["gs_ibl_GS-IBL_Probe_irradiance.exr",
                                                "gs_ibl_GS-IBL_Probe_radiance.exr",
                                                "gs_ibl_GS-IBL_Probe_radiance_1.exr", "scene.blend"]
        np.testing.assert_allclose(gw.image_latlong_pixels(s.radiance_image), k * rad, rtol=1e-6)
        # the file itself holds the linear floats (read by OpenImageIO, not by Blender, which would undo its own
        # encoding): what a compositor or another renderer will see
        on_disk = read_exr(bpy.path.abspath(s.radiance_image.filepath))
        import OpenImageIO as oiio
        stored = oiio.ImageInput.open(bpy.path.abspath(s.radiance_image.filepath))
        assert str(stored.spec().format) == "float"  # 32-bit in the file, not half
        stored.close()
        np.testing.assert_allclose(on_disk[..., :3], k * rad, rtol=1e-6)
    # a file counts as ours only for the image that wrote it: any other writer moves on to a free name
    assert gw.our_file_path(str(tmp_path), "gs_ibl_GS-IBL_Probe_radiance", s.radiance_image) == \
        str(tmp_path / "gs_ibl_GS-IBL_Probe_radiance_1.exr")
    assert gw.our_file_path(str(tmp_path), "gs_ibl_GS-IBL_Probe_radiance", None) == \
        str(tmp_path / "gs_ibl_GS-IBL_Probe_radiance_2.exr")


def test_proxy_material_and_tree_found_by_marker_not_name(blender):
    """A user's material and node group named like the proxy's are left alone, and every import shares one of ours."""
    from gs_ibl_addon.blender.splats.object import PROXY_MATERIAL, PROXY_MODIFIER, PROXY_TREE, create_splat_object
    user_mat = bpy.data.materials.new(PROXY_MATERIAL)
    user_mat.diffuse_color = (1.0, 0.0, 0.0, 1.0)
    user_tree = bpy.data.node_groups.new(PROXY_TREE, "GeometryNodeTree")
    a = create_splat_object(bpy.context, random_scene(20, sh_degree=1), "A")
    b = create_splat_object(bpy.context, random_scene(30, sh_degree=1), "B")
    tree = a.modifiers[PROXY_MODIFIER].node_group
    assert tree != user_tree and b.modifiers[PROXY_MODIFIER].node_group == tree
    assert [t for t in bpy.data.node_groups if t.get("gs_ibl")] == [tree]
    ours = [m for m in bpy.data.materials if m.get("gs_ibl")]
    assert len(ours) == 1 and ours[0] != user_mat
    assert user_mat.name == PROXY_MATERIAL and tuple(user_mat.diffuse_color) == (1.0, 0.0, 0.0, 1.0)
    assert user_tree.name == PROXY_TREE and len(user_tree.nodes) == 0 and "gs_ibl" not in user_tree.keys()
    assert "gs_ibl" not in user_mat.keys()


def test_each_probe_has_its_world_and_strength(blender):
    """Probes in two scenes bake into two Worlds; a probe's Strength changes its own World only; a re-bake
    rebuilds the probe's World in place; a duplicated probe gets a World of its own."""
    from gs_ibl_addon.blender.lighting import world as gw
    from gs_ibl_addon.blender.lighting.bake import apply_probe_images

    def strength(world):
        return world.node_tree.nodes["GS-IBL Strength"].inputs["Strength"].default_value

    def radiance(world):
        return gw.image_latlong_pixels(world.node_tree.nodes["GS-IBL Radiance"].image)

    def ours():
        return [w for w in bpy.data.worlds if w.get("gs_ibl")]

    scene1, scene2 = bpy.context.scene, bpy.data.scenes.new("Other")
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    p1 = bpy.context.active_object
    p2 = bpy.data.objects.new("Probe 2", None)
    p2.gs_ibl_probe.is_probe = True
    scene2.collection.objects.link(p2)
    rad1, rad2 = (np.full((8, 16, 3), v, np.float32) for v in (0.2, 0.7))
    irr = np.full((4, 8, 3), 0.25, np.float32)
    w1 = apply_probe_images(scene1, p1, rad1, irr)
    w2 = apply_probe_images(scene2, p2, rad2, irr)
    assert w1 != w2 and scene1.world == w1 and scene2.world == w2 and len(ours()) == 2
    np.testing.assert_allclose(radiance(w1), rad1)
    np.testing.assert_allclose(radiance(w2), rad2)  # each World shows its own probe's light
    p1.gs_ibl_probe.strength = 3.0
    assert strength(w1) == pytest.approx(3.0) and strength(w2) == pytest.approx(1.0)
    p2.gs_ibl_probe.strength = 0.5
    assert strength(w1) == pytest.approx(3.0) and strength(w2) == pytest.approx(0.5)
    w1 = apply_probe_images(scene1, p1, 2 * rad1, irr)
    assert len(ours()) == 2 and scene1.world == w1 == p1.gs_ibl_probe.world and scene2.world == w2
    np.testing.assert_allclose(radiance(w1), 2 * rad1)
    np.testing.assert_allclose(radiance(w2), rad2)
    p3 = p1.copy()  # Shift+D copies the probe's references to its World and images
    scene1.collection.objects.link(p3)
    w3 = apply_probe_images(scene1, p3, rad2, irr)
    assert len(ours()) == 3 and w3 != w1 and p1.gs_ibl_probe.world == w1
    np.testing.assert_allclose(radiance(w1), 2 * rad1)
    p3.gs_ibl_probe.strength = 5.0
    assert strength(w1) == pytest.approx(3.0) and strength(w3) == pytest.approx(5.0)


def test_add_probe_at_selected_mesh(blender):
    bpy.ops.mesh.primitive_cube_add(location=(2.0, -1.0, 0.5))
    bpy.ops.gs_ibl.add_probe(place="SELECTED")
    probe = bpy.context.active_object
    np.testing.assert_allclose(probe.location, (2.0, -1.0, 0.5), atol=1e-6)


def test_bake_reports_clear_error_without_splats(blender):
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    with pytest.raises(RuntimeError, match="No splat object"):
        bpy.ops.gs_ibl.bake_probe()


def test_probe_result_cubes_become_latlong_images(blender):
    """The bake writes a core ProbeResult (cubes) as lat-long images in Blender's mapping."""
    from gs_ibl_addon.blender.lighting import world as gw
    from gs_ibl_addon.blender.lighting.bake import apply_probe_images, result_latlong
    from gs_ibl_addon.core.cubemap import latlong_directions
    from gs_ibl_addon.core.probe import ProbeResult
    from gs_ibl_addon.core.probe.reference import cube_from_function

    def radiance(d):  # smooth, with x, y and z terms per channel
        return 0.5 + d @ np.array([[0.3, 0.1, 0.05], [0.0, -0.2, 0.1], [0.1, 0.1, -0.3]]).T * 0.9

    def irradiance(n):
        return 0.5 + (2.0 / 3.0) * n @ np.array([[0.3, 0.1, 0.05], [0.0, -0.2, 0.1], [0.1, 0.1, -0.3]]).T * 0.9

    result = ProbeResult(radiance=cube_from_function(radiance, 64).astype(np.float32),
                         irradiance=cube_from_function(irradiance, 16).astype(np.float32))
    rad = result_latlong(result, "radiance", 64)
    irr = result_latlong(result, "irradiance", 16)
    assert rad.shape == (64, 128, 3) and irr.shape == (16, 32, 3)
    np.testing.assert_allclose(rad, radiance(latlong_directions(128, 64).reshape(-1, 3)).reshape(64, 128, 3),
                               atol=2e-3)
    np.testing.assert_allclose(irr, irradiance(latlong_directions(32, 16).reshape(-1, 3)).reshape(16, 32, 3),
                               atol=1e-2)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    w = apply_probe_images(bpy.context.scene, bpy.context.active_object, rad, irr)
    np.testing.assert_allclose(gw.image_latlong_pixels(w.node_tree.nodes["GS-IBL Radiance"].image), rad)
