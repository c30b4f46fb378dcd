"""Shadows on Splats in F12 (blender/render/frame.py + core/render/shadows.py, issue 36 item 3), in the bpy module.

The target, small: tests/shadow_scene.py's sphere over a splat floor under a sun-like splat sky, 80x60. Ours is
the floor's F12 with the setting on over off; the reference is Cycles path tracing a diffuse plane of the splats'
colour in the same World with the sphere over without it (64 spp, 4 bounces: the grey sphere's reflected light
in its shadow, which ours adds from its material's colour). The darkening D = 1 - ratio must agree within 10 % of
Cycles': over the shadowed region, over the whole floor, and per pixel (3x3 box filtered, median over the pixels
ours darkens by more than 0.2). The full-size numbers are benchmarks/shadow_bench.py's.
"""
from __future__ import annotations

import numpy as np

import shadow_scene as S

TOLERANCE = 0.10  # the target: |D_ours - D_cycles| within 10 % of D_cycles


def test_shadow_of_a_sphere_on_a_splat_floor_matches_cycles(blender, tmp_path):
    parts = S.build(blender, 80, 60, samples=1)
    on, off, record = S.ours(blender, parts, tmp_path)
    assert record["messages"] == [] and record["light_samples"] > 0 and record["ms_shadows"] > 0, record
    sphere = S.sphere_mask(blender, parts, tmp_path)
    with_sphere, without = S.cycles(blender, parts, tmp_path, 64)
    c = S.compare(on, off, with_sphere, without, sphere)
    summary = {k: v for k, v in c.items() if not isinstance(v, np.ndarray)}
    assert c["pixels"] > 150 and c["d_cycles"] > 0.15, summary  # a real shadow, in the frame
    assert c["rel"] < TOLERANCE, summary
    assert abs(c["floor_d_ours"] - c["floor_d_cycles"]) < TOLERANCE * c["floor_d_cycles"], summary
    assert c["pixel_rel_median"] < TOLERANCE, summary
    # the capture's coverage and the pixels away from the sphere are untouched
    np.testing.assert_array_equal(on[..., 3], off[..., 3])
    far = ~c["region"] & np.isfinite(c["D_ours"])
    assert np.abs(c["D_ours"][far]).max() < 0.06


def test_no_baked_probe_no_shadows_and_it_is_said(blender, tmp_path):
    from gs_ibl_addon.blender.render import frame
    parts = S.build(blender, 32, 24, samples=1)
    world = blender.data.worlds.new("Plain")
    parts["scene"].world = world
    on = S.render(blender, tmp_path / "on.exr")
    messages = frame.last_render(parts["scene"])["messages"]
    assert len(messages) == 1 and "not a baked probe's" in messages[0], messages
    parts["scene"].gs_ibl_render.shadows = False
    off = S.render(blender, tmp_path / "off.exr")
    assert frame.last_render(parts["scene"])["messages"] == []
    np.testing.assert_array_equal(on, off)


def test_the_probes_split_lights_are_in_its_light(blender, tmp_path):
    from gs_ibl_addon.blender.lighting import lights_from_probe
    from gs_ibl_addon.blender.render import frame
    assert frame.PROBE_OWNER_KEY == lights_from_probe.OWNER_KEY
    parts = S.build(blender, 32, 24, samples=1)
    scene = parts["scene"]
    env_only, why = frame.probe_light(scene)
    assert why is None and env_only.count > 0
    blender.ops.gs_ibl.add_probe(place="CURSOR")
    probe = blender.context.active_object
    probe.gs_ibl_probe.world = scene.world
    sun = {"direction": [0.0, 0.6, 0.8], "irradiance": [3.0, 2.0, 1.0], "angle": 4.0}
    lights_from_probe.sync_lights(scene, probe, [sun])
    blender.context.view_layer.update()  # the sun's matrix_world (a render's depsgraph has evaluated it)
    samples, why = frame.probe_light(scene)
    assert samples.count == env_only.count + 24
    np.testing.assert_allclose(samples.weights.sum(0), env_only.weights.sum(0) + sun["irradiance"], rtol=1e-5)
    mean_dir = samples.directions[env_only.count:].mean(0)
    np.testing.assert_allclose(mean_dir / np.linalg.norm(mean_dir), sun["direction"], atol=1e-3)
