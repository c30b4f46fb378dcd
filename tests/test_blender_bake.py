"""Baking inside Blender: import a splat file, add a probe, bake with the core's bake_probe, and check what landed
in the World against the core's own result; hole warnings; headless baking; re-bake when moved."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gs_ibl_addon.core.bake import ProbeSettings, bake_probe  # noqa: E402
from gs_ibl_addon.core.cubemap import latlong_directions  # noqa: E402
from gs_ibl_addon.core.probe.latlong import cube_to_latlong  # noqa: E402
from gs_ibl_addon.core.synthetic import SkyGradient, room_scene, shell_scene  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKY = SkyGradient()
SHELL_N, SHELL_R = 6000, 5.0


def _world_images():
    from gs_ibl_addon.blender.lighting import world as gw
    rad = gw.image_latlong_pixels(bpy.context.scene.world.node_tree.nodes["GS-IBL Radiance"].image)
    irr = gw.image_latlong_pixels(bpy.data.node_groups["GS-IBL Irradiance"].nodes["GS-IBL Irradiance Image"].image)
    return rad, irr


def _import_shell(tmp_path, write_3dgs_ply, center=(0.0, 0.0, 0.0)):
    path = tmp_path / "shell.ply"
    write_3dgs_ply(path, shell_scene(SKY, SHELL_N, SHELL_R, center))
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), axis_preset="BLENDER", show_proxy=False) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.gs_ibl_splats.colour_space == "SRGB"  # the file declares nothing: Blender's rule
    obj.gs_ibl_splats.colour_space = "LINEAR"  # the shell's colours are linear radiance
    return obj


def test_bake_operator_matches_core_result(blender, tmp_path, write_3dgs_ply):
    """Import a PLY shell, add a probe, bake through the operator: the World's images are the core's result, and
    the irradiance is the shell's known one (a + 2/3 b n_z)."""
    from gs_ibl_addon.blender.splats.object import scene_from_object
    splats = _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    s = probe.gs_ibl_probe
    assert s.splats == splats and s.face_size == 0 and s.method == "AUTO" and not s.auto_update
    s.face_size, s.irradiance_size, s.method = 32, 8, "CONV"
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    rad, irr = _world_images()
    core = bake_probe(scene_from_object(splats), (0.0, 0.0, 0.0),
                      ProbeSettings(method="conv", face_size=32, irradiance_size=8))
    want_rad = cube_to_latlong(core.radiance[..., :3], 4 * 32)
    want_irr = cube_to_latlong(core.irradiance, 64)  # lat-long width max(64, 4 x face), as write_probe
    assert rad.shape == want_rad.shape == (64, 128, 3) and irr.shape == want_irr.shape == (32, 64, 3)
    np.testing.assert_allclose(rad, want_rad, rtol=1e-5, atol=1e-6)  # same renderer, same input: identical
    np.testing.assert_allclose(irr, want_irr, rtol=1e-5, atol=1e-6)
    known = SKY.irradiance_over_pi(latlong_directions(64, 32).reshape(-1, 3)).reshape(32, 64, 3)
    rel = np.abs(irr - known) / known
    print(f"\nshell bake: irradiance vs a + 2/3 b n_z: max rel. error {rel.max():.4f}, mean {rel.mean():.4f}")
    assert rel.max() < 0.02  # the shell blurs its radiance over one splat spacing; holes would show as > 10%
    report = s.last_report
    assert "render" in report and "filter" in report and "conv" in report and "holes" not in report
    assert bpy.context.scene.world.get("gs_ibl") == "world"


def test_report_parts_add_up_to_its_total(blender, tmp_path, write_3dgs_ply):
    """The report names where the time went, and its parts add up to the total (a 3M re-bake once said
    "render 3277 ms, filter 11 ms, total 10.43 s" and nothing of the other 7 s)."""
    import re
    _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 16, 8
    for first in (True, False):  # the first bake reads, turns and uploads the splats; the second finds them
        assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
        line = next(x for x in probe.gs_ibl_probe.last_report.split("\n") if "the total:" in x)
        total = float(re.search(r"total ([0-9.]+) s", line).group(1))
        parts = {k.strip(", "): float(v)
                 for k, v in re.findall(r"([A-Za-z' ]+?) ([0-9.]+) s", line.split("the total: ")[1])}
        made = {"reading", "turning SH", "upload"}
        assert {"bake", "writing", "other"} <= set(parts) and (made <= set(parts)) == first, line
        assert sum(parts.values()) == pytest.approx(total, abs=0.03), line


def test_auto_reports_choice_and_error(blender, tmp_path, write_3dgs_ply):
    shell = _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size = 0  # auto: doubled until the irradiance stops moving
    probe.gs_ibl_probe.tolerance = 0.05
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    lines = probe.gs_ibl_probe.last_report.split("\n")
    # a smooth sky converges at once: 32 -> 64 moves the irradiance by far less than 5%
    assert lines[0].endswith("64x64 faces"), lines
    assert lines[1].startswith("exact; face size by irradiance change (64: ") and lines[1].endswith(" converged"), lines
    # the splat cache's host copy (base colour only) gives the near-splat check its splats
    from gs_ibl_addon.blender.splats import cache as splat_cache
    entry = splat_cache.get(shell)
    assert entry.host.sh.shape == (entry.renderer.scene_count, 1, 3)
    assert "(change model)" in probe.gs_ibl_probe.last_report, lines


def test_hole_warning(blender):
    """A room with a window and a skylight: the probe sees the openings, and the report says how much."""
    from gs_ibl_addon.blender.lighting.bake import bake_into_world
    from gs_ibl_addon.blender.splats.object import create_splat_object
    room = room_scene((3.0, 3.0, 2.5), spacing=0.15, window=((-1.0, 1.0), (0.5, 2.0)), skylight=((-1.0, 1.0), (-1.0, 1.0)))
    create_splat_object(bpy.context, room.scene, "room", proxy=False)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.location = (0.0, 0.0, 1.2)
    probe.gs_ibl_probe.face_size = 16
    bpy.context.view_layer.update()
    result, _text, warning = bake_into_world(bpy.context.scene, probe)
    assert result.hole_fraction > 0.05
    assert warning.startswith(f"the probe sees holes: {100 * result.hole_fraction:.1f}% of directions have no splat")
    assert warning in probe.gs_ibl_probe.last_report


def test_bake_headless_from_saved_blend(blender, tmp_path, write_3dgs_ply):
    """The documented headless use: open a saved .blend in a fresh process, bake, save; the bake is in the file."""
    _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    bpy.context.active_object.gs_ibl_probe.face_size = 16
    bpy.context.active_object.select_set(False)
    bpy.context.view_layer.objects.active = None  # nothing selected: the operator finds the probe by itself
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    # With a Blender binary: blender -b scene.blend --python-expr "import bpy; bpy.ops.gs_ibl.bake_probe(); ..."
    # (the extension enabled in Preferences). The bpy module has no Preferences: the script registers it.
    code = textwrap.dedent(f"""
        import bpy, gs_ibl_addon
        gs_ibl_addon.register()
        bpy.ops.wm.open_mainfile(filepath={blend!r})
        assert bpy.ops.gs_ibl.bake_probe() == {{"FINISHED"}}
        bpy.ops.wm.save_mainfile()
    """)
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": ROOT})
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "GS-IBL: rendering a 16x16 cubemap" in r.stdout  # progress is printed in background mode
    bpy.ops.wm.open_mainfile(filepath=blend)
    _rad, irr = _world_images()
    known = SKY.irradiance_over_pi(latlong_directions(64, 32).reshape(-1, 3)).reshape(32, 64, 3)
    np.testing.assert_allclose(irr, known, rtol=0.03)


def test_update_when_moved(blender, tmp_path, write_3dgs_ply):
    """The depsgraph handler notes a really moved probe and (re)starts one debounce timer; the timer re-bakes once;
    the bake's own updates, and updates that move nothing, schedule nothing (once, every bake scheduled the next)."""
    from gs_ibl_addon.blender.lighting import auto_update as au
    splats = _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    s = probe.gs_ibl_probe
    s.face_size, s.irradiance_size = 16, 8
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    _, irr0 = _world_images()
    probe.location = (0.0, 0.0, 3.0)  # off by default: nothing is scheduled
    bpy.context.view_layer.update()
    assert not au._pending and not bpy.app.timers.is_registered(au.run_pending)
    s.auto_update = True
    s.update_interval = 2.0
    probe.location = (0.0, 0.0, 3.5)  # 0.7 of the radius up: the view of the sky gradient changes
    bpy.context.view_layer.update()
    assert au._pending == {(bpy.context.scene.name, probe.name)}
    assert bpy.app.timers.is_registered(au.run_pending)
    splats.location = (0.0, 0.0, 0.01)  # moving the splats as well keeps one pending bake, one timer
    bpy.context.view_layer.update()
    assert len(au._pending) == 1
    # Timers only run in Blender's event loop (not in the bpy module): run the timer's function as Blender would.
    bpy.app.timers.unregister(au.run_pending)
    before = au.auto_bakes
    assert au.run_pending() is None and not au._pending and au.last_auto_error is None
    assert au.auto_bakes == before + 1
    _, irr1 = _world_images()
    assert not np.allclose(irr0, irr1, rtol=0.01)
    from gs_ibl_addon.blender.splats.object import scene_from_object
    core = bake_probe(scene_from_object(splats), np.array(probe.matrix_world.translation),
                      ProbeSettings(face_size=16, irradiance_size=8))
    np.testing.assert_allclose(irr1, cube_to_latlong(core.irradiance, 64), rtol=1e-5, atol=1e-6)
    # what the bake wrote (images, World, the probe's report) and updates that move nothing schedule nothing
    bpy.context.view_layer.update()
    probe.location = probe.location  # a transform update to the same place
    probe.rotation_euler = (0.3, 0.0, 0.0)  # a probe's rotation does not change its light
    s.strength = 1.5
    bpy.context.view_layer.update()
    assert not au._pending and not bpy.app.timers.is_registered(au.run_pending)
    # moved and moved back before the timer fired: the timer finds nothing to do
    probe.location = (0.0, 0.0, 3.0)
    bpy.context.view_layer.update()
    assert au._pending and bpy.app.timers.is_registered(au.run_pending)
    probe.location = (0.0, 0.0, 3.5)
    bpy.context.view_layer.update()
    bpy.app.timers.unregister(au.run_pending)
    assert au.run_pending() is None and au.auto_bakes == before + 1


def test_report_gives_the_filters_gpu_time():
    """The report's filter time is the filters' GPU time (SH projection + irradiance, + GGX when baked), not every
    timing key: host wall times, per-step splits and the upload would count the same work two or three times."""
    from gs_ibl_addon.blender.lighting.bake import summary
    scene = shell_scene(SKY, 2000, SHELL_R)
    for glossy in (False, True):
        result = bake_probe(scene, (0.0, 0.0, 0.0), ProbeSettings(method="exact", face_size=16, irradiance_size=8,
                                                                  glossy=glossy))
        t = result.timings_ms
        assert "filter_wall" in t and "upload" not in t  # the rendered frame is filtered where it is, on the GPU
        assert any(k.startswith("irradiance.") for k in t)
        want = t["irradiance"] + t["sh_project"] + (t["ggx"] if glossy else 0.0)
        assert ("ggx" in t) == glossy
        lines, _ = summary(result, 1.0)
        assert f"render {t['render_total']:.0f} ms, filter {want:.0f} ms, total 1.00 s" in lines[2], lines
        everything = sum(v for k, v in t.items() if not k.startswith("render_") and k != "bake_wall")
        assert want < everything - 1.0  # the old sum: the wall times alone add about as much again


def test_bakes_and_overlay_share_one_upload(blender, tmp_path, write_3dgs_ply):
    """Re-bakes of an unchanged splat object and the viewport overlay use one renderer (one upload); moving,
    scaling or editing the object uploads it again, and the bake then matches the core's for the changed object."""
    from gs_ibl_addon.blender.viewport import overlay_images
    from gs_ibl_addon.blender.splats import cache as splat_cache
    from gs_ibl_addon.blender.lighting.bake import bake_into_world
    from gs_ibl_addon.blender.splats.object import scene_from_object
    splats = _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 16, 8
    scene = bpy.context.scene
    bpy.context.view_layer.update()
    n0 = splat_cache.uploads
    bake_into_world(scene, probe)
    assert splat_cache.uploads == n0 + 1  # the bake read and uploaded the splats through the cache
    renderer = splat_cache.get(splats).renderer
    bake_into_world(scene, probe)
    assert splat_cache.uploads == n0 + 1 and splat_cache.get(splats).renderer is renderer
    assert overlay_images.overlay_for(splats).renderer is renderer and splat_cache.uploads == n0 + 1

    def changed(step: int) -> None:
        bpy.context.view_layer.update()
        result, _, _ = bake_into_world(scene, probe)
        assert splat_cache.uploads == n0 + step and splat_cache.get(splats).renderer is not renderer
        assert overlay_images.overlay_for(splats).renderer is splat_cache.get(splats).renderer
        core = bake_probe(scene_from_object(splats), (0.0, 0.0, 0.0), ProbeSettings(face_size=16, irradiance_size=8))
        np.testing.assert_allclose(result.irradiance, core.irradiance, rtol=1e-5, atol=1e-6)

    splats.location = (0.0, 0.0, 1.0)
    changed(2)
    renderer = splat_cache.get(splats).renderer
    splats.scale = (1.5, 1.5, 1.5)
    changed(3)
    renderer = splat_cache.get(splats).renderer
    co = np.empty(3 * len(splats.data.vertices), np.float32)  # an edit that keeps the vertex count
    splats.data.vertices.foreach_get("co", co)
    splats.data.vertices.foreach_set("co", co * 0.9)
    splats.data.update()
    changed(4)
    bpy.data.objects.remove(splats)  # a deleted object's splats leave the GPU at the next update
    bpy.context.view_layer.update()
    assert not splat_cache._entries


@pytest.mark.parametrize("scale, words", [
    pytest.param((1.0, 2.0, 1.0), ("non-uniformly", "same scale on all three axes"), id="non-uniform"),
    pytest.param((-1.0, 1.0, 1.0), ("mirrors", "same scale on all three axes"), id="mirrored"),
])
def test_bake_names_a_splat_object_it_cannot_transform(blender, scale, words):
    """Splats cannot follow a non-uniform or mirrored object scale: the bake is cancelled with a message naming
    the object (no traceback, nothing written), and the overlay says the same."""
    from gs_ibl_addon.blender.viewport import overlay_images
    from gs_ibl_addon.blender.splats.object import create_splat_object
    obj = create_splat_object(bpy.context, shell_scene(SKY, 500, SHELL_R), "Stretched Room", proxy=False)
    obj.scale = scale
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size = 16
    bpy.context.view_layer.update()
    before = (len(bpy.data.worlds), len(bpy.data.images), len(bpy.data.node_groups))
    with pytest.raises(RuntimeError) as e:  # bpy.ops raises on an ERROR report: the operator was cancelled
        bpy.ops.gs_ibl.bake_probe()
    msg = str(e.value)
    assert "Stretched Room: " in msg and "Traceback" not in msg, msg
    assert all(w in msg for w in words), msg
    assert (len(bpy.data.worlds), len(bpy.data.images), len(bpy.data.node_groups)) == before
    assert probe.gs_ibl_probe.last_report == ""
    with pytest.raises(ValueError, match="^Stretched Room: "):
        overlay_images.overlay_for(obj)


def test_demo_script_runs(tmp_path):
    """scripts/blender_demo.py end to end at a tiny size: PNG and .blend written, meshes lit (not black)."""
    OpenImageIO = pytest.importorskip("OpenImageIO")
    out = tmp_path / "demo.png"
    r = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "blender_demo.py"), "--out", str(out),
                        "--width", "80", "--height", "60", "--samples", "4", "--face-size", "32",
                        "--splats-png", str(tmp_path / "splats.png")],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "bake:" in r.stdout and "Cycles 80x60" in r.stdout
    px = np.asarray(OpenImageIO.ImageBuf(str(out)).get_pixels(OpenImageIO.FLOAT))
    assert px.shape[:2] == (60, 80) and 0.1 < px[..., :3].mean() < 0.9
    splats = np.asarray(OpenImageIO.ImageBuf(str(tmp_path / "splats.png")).get_pixels(OpenImageIO.FLOAT))
    assert splats.shape[:2] == (60, 80) and splats.mean() > 0.1
    assert (tmp_path / "demo.blend").is_file()


def test_bake_refuses_a_size_that_does_not_fit_before_uploading(blender, tmp_path, write_3dgs_ply, monkeypatch):
    """The panel's bake checks the face size against free memory before the splats are read or uploaded, and says
    which size fits (the command line's check: core/limits.py)."""
    from gs_ibl_addon.blender.splats import cache as splat_cache
    from gs_ibl_addon.core import limits
    _import_shell(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size = 1024
    monkeypatch.setattr(limits, "host_available", lambda: 64 << 20)  # 64 MiB free
    uploads = splat_cache.uploads
    with pytest.raises(RuntimeError, match=r"1024\^2 faces needs about .* use \d+ or less"):
        bpy.ops.gs_ibl.bake_probe()  # the operator's ERROR report surfaces as RuntimeError in the bpy module
    assert splat_cache.uploads == uploads and probe.gs_ibl_probe.world is None


def test_native_splats_light_once(blender, tmp_path, write_3dgs_ply, monkeypatch):
    """With our World assigned, Blender 5.3's native splats stop lighting meshes through Cycles' bounces (their
    light is in the World), camera rays still see them, and Restore Previous World gives the bounces back exactly
    as they were. (bpy 5.0 has no native splats: an ordinary object stands in for one here; the bpy 5.3 run of
    tests/real_blender/test_native_splats.py does it with a real one.)"""
    from gs_ibl_addon.blender.splats import object as splat_object
    shell = _import_shell(tmp_path, write_3dgs_ply)
    bpy.context.scene.world = bpy.data.worlds.new("The user's World")
    bpy.ops.mesh.primitive_cube_add()
    native = bpy.context.active_object
    native.visible_glossy = False  # the user's own setting, to be given back as it was
    native.hide_render = True  # a real one shown in renders would light the probe too; a cube has no splats to read
    monkeypatch.setattr(splat_object, "is_native_splats", lambda o: o is not None and o.name == native.name)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 16, 8
    probe.gs_ibl_probe.splats = shell  # the stand-in is only to be muted, not baked from
    assert probe.gs_ibl_probe.mute_native_splats
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert not native.visible_diffuse and not native.visible_glossy and not native.visible_shadow
    assert native.visible_camera
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}  # a re-bake keeps the first saved state
    assert bpy.ops.gs_ibl.restore_world() == {"FINISHED"}
    assert native.visible_diffuse and not native.visible_glossy and native.visible_shadow
    assert "gs_ibl_ray_visibility" not in native.keys()
    probe.gs_ibl_probe.mute_native_splats = False
    assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
    assert native.visible_diffuse


def shell_and_ball(tmp_path, write_3dgs_ply):
    """Two splat objects imported: a grey shell of radius 3 m about the origin and a red ball at (0.6, 0, 0)
    (another capture beside a probe at the origin)."""
    from gs_ibl_addon.core import synthetic
    shell = synthetic.shell_scene(lambda d: np.full(d.shape, 0.3), 1500, radius=3.0)
    ball = synthetic.sphere_object((0.6, 0.0, 0.0), 0.2, (0.9, 0.05, 0.05), 0.05)
    for name, sc in (("shell", shell), ("ball", ball)):
        write_3dgs_ply(tmp_path / f"{name}.ply", sc)
        assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(tmp_path / f"{name}.ply"),
                                            show_proxy=False) == {"FINISHED"}
    return bpy.data.objects["shell"], bpy.data.objects["ball"]


def test_every_splat_object_shown_in_renders_lights_the_probe(blender, tmp_path, write_3dgs_ply):
    """Issue 37: a grey shell (the probe's own splats) and a red ball beside the probe (another capture): the
    World probe is baked from both, merged and sorted together (the report says "from 2 splat objects"), and its
    irradiance is redder than with the ball hidden from renders. Moving the ball, hiding it, or giving it another
    colour space (merged by Blender's rule, as F12 draws a mix) marks the bake out of date, and says which."""
    from gs_ibl_addon.blender.lighting.stale import stale_reasons
    from gs_ibl_addon.blender.splats import cache as splat_cache
    shell_obj, ball_obj = shell_and_ball(tmp_path, write_3dgs_ply)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.splats = shell_obj
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 32, 8
    probe.gs_ibl_probe.lighting = "WORLD"
    scene = bpy.context.scene

    def bake():
        bpy.context.view_layer.objects.active = probe
        assert bpy.ops.gs_ibl.bake_probe() == {"FINISHED"}
        _rad, irr = _world_images()
        return probe.gs_ibl_probe.last_report, irr[..., :3].reshape(-1, 3).mean(0)

    uploads = splat_cache.uploads
    both_report, both = bake()
    assert splat_cache.uploads == uploads + 1  # one merged copy of both (each object's own is not needed)
    bake()
    assert splat_cache.uploads == uploads + 1  # kept for the next bake
    assert "from 2 splat objects: shell, ball" in both_report
    assert "2 splat objects" in probe.gs_ibl_probe.last_summary
    from tests.panel_recorder import draw_panel
    shown = " ".join(text for text, _icon in draw_panel().get("labels", []))
    assert "With ball (shown in renders)" in shown  # under the probe's Splats field, which names the shell alone
    assert stale_reasons(scene, probe) == []
    ball_obj.location.x += 0.1
    bpy.context.view_layer.update()
    assert "'ball' moved" in stale_reasons(scene, probe)
    ball_obj.location.x -= 0.1
    ball_obj.hide_render = True
    bpy.context.view_layer.update()
    assert "'ball' no longer lights it" in stale_reasons(scene, probe)
    one_report, one = bake()
    assert not [k for k in splat_cache._entries if isinstance(k, tuple)]  # the merged copy was given back
    print(f"\nmean irradiance: both {np.round(both, 4)}, the shell alone {np.round(one, 4)}")
    assert "splat objects" not in one_report
    assert both[0] / both[2] > 1.05 * one[0] / one[2]  # redder with the ball
    # shown in renders but in a collection the view layer excludes: F12 leaves it out, and so does the light
    ball_obj.hide_render = False
    excluded = bpy.data.collections.new("excluded")
    scene.collection.children.link(excluded)
    for c in list(ball_obj.users_collection):
        c.objects.unlink(ball_obj)
    excluded.objects.link(ball_obj)
    bpy.context.view_layer.layer_collection.children[excluded.name].exclude = True
    bpy.context.view_layer.update()
    assert stale_reasons(scene, probe) == []  # as it was baked: the shell alone
    excluded_report, out = bake()
    assert "splat objects" not in excluded_report and np.allclose(out, one)
    bpy.context.view_layer.layer_collection.children[excluded.name].exclude = False
    bpy.context.view_layer.update()
    assert "'ball' now lights it" in stale_reasons(scene, probe)
    bpy.context.view_layer.layer_collection.children[excluded.name].exclude = True
    bpy.context.view_layer.update()
    # another colour space: merged as F12 draws a mix (Blender's rule, the linear one re-encoded), still lighting it
    bpy.context.view_layer.layer_collection.children[excluded.name].exclude = False
    ball_obj.gs_ibl_splats.colour_space = "LINEAR" if shell_obj.gs_ibl_splats.colour_space == "SRGB" else "SRGB"
    bpy.context.view_layer.update()
    assert "'ball' now lights it" in stale_reasons(scene, probe)
    mixed_report, mixed = bake()
    assert "from 2 splat objects: shell, ball" in mixed_report and mixed[0] / mixed[2] > 1.05 * one[0] / one[2]
    # Update When Moved follows every object that lights the probe
    from gs_ibl_addon.blender.lighting import auto_update as au
    ball_obj.gs_ibl_splats.colour_space = shell_obj.gs_ibl_splats.colour_space
    bake()
    probe.gs_ibl_probe.auto_update = True
    ball_obj.location.x += 0.2
    bpy.context.view_layer.update()
    assert au._pending == {(scene.name, probe.name)} and bpy.app.timers.is_registered(au.run_pending)
    bpy.app.timers.unregister(au.run_pending)
    before = au.auto_bakes
    assert au.run_pending() is None and au.auto_bakes == before + 1 and au.last_auto_error is None
    assert stale_reasons(scene, probe) == []
