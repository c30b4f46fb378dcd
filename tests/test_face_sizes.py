"""Face size 0 sizes each cube face by itself (core/bake.py choose_face_sizes): a lamp's face is rendered finer,
the rest stay coarse, and the irradiance still meets the tolerance against a fine uniform render."""
import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.bake import RADIANCE_OUT_MAX, ProbeSettings, bake_probe, relative_rms
from gs_ibl_addon.core.probe.box import downsample_cube, faces_to_size
from gs_ibl_addon.core.probe.reference import exact_irradiance_cube, exact_irradiance_parts
from gs_ibl_addon.core.synthetic import SkyGradient, sample_environment, shell_scene
from gs_ibl_addon.core.tolerance import TAIL_RATIO_RANGE, ErrorModel, tail

LAMP_AT = [0.0, 0.0, 1.0]  # the sample environment's probe: its lamp is straight above, in the +Z face


def _shuffled(scene, seed=3):
    order = np.random.default_rng(seed).permutation(scene.count)
    return scene.subset(order)


@pytest.fixture(scope="module")
def lamp_room():
    return _shuffled(sample_environment())


def test_faces_to_size_keeps_each_texels_light():
    rng = np.random.default_rng(0)
    cube = rng.random((6, 32, 32, 4))
    np.testing.assert_allclose(faces_to_size(cube, 8), downsample_cube(downsample_cube(cube)), rtol=1e-12)
    w32, w8 = cubemap.texel_solid_angles(32), cubemap.texel_solid_angles(8)
    # the solid-angle-weighted light of the face is the same at both sizes
    np.testing.assert_allclose((faces_to_size(cube, 8) * w8[None, ..., None]).sum((1, 2)),
                               (cube * w32[None, ..., None]).sum((1, 2)), rtol=1e-10)
    up = faces_to_size(cube[:2], 64)
    assert up.shape == (2, 64, 64, 4)
    np.testing.assert_allclose(up.mean((1, 2)), cube[:2].mean((1, 2)), rtol=0.02)


def test_a_change_splits_into_each_faces_part():
    cube = np.random.default_rng(1).random((6, 64, 64, 3))
    parts = exact_irradiance_parts(cube, 8, downsample_to=32)
    assert parts.shape == (6, 6, 8, 8, 3)
    np.testing.assert_allclose(parts.sum(0), exact_irradiance_cube(cube, 8, downsample_to=32), rtol=1e-12)
    only = np.zeros_like(cube)
    only[2] = cube[2]
    np.testing.assert_allclose(parts[2], exact_irradiance_cube(only, 8, downsample_to=32), rtol=1e-12)


def test_the_plan_refines_the_face_whose_part_is_largest():
    irr = np.ones((6, 8, 8, 3))
    parts = np.zeros((6, 6, 8, 8, 3))
    z = cubemap.FACE_NAMES.index("+Z")
    parts[z] = 0.03  # as if 32^2 -> 64^2 had moved the irradiance by 3.1%, 3% of it from the +Z face
    parts[0] = 0.001
    model = ErrorModel()
    model.calibrate(32, 64, 0.031)
    model.take_parts(parts, [32] * 6, [64] * 6, irr)
    assert model.estimate_faces([64] * 6) == pytest.approx(0.031)
    sizes, est = model.plan_faces(0.01, 1024)
    assert sizes[z] == 256 and sizes.count(64) == 5 and est == pytest.approx(0.03 / 4 + 0.001)  # two doublings
    assert est == pytest.approx(model.estimate_faces(sizes))
    assert model.next_sizes(0.01, 1024) == [64, 64, 64, 64, 128, 64]  # rendered one doubling at a time
    # a face measured again keeps its new part and measures its own fall (0.3% / 3% over one doubling: 0.1,
    # clamped to 0.35); the others keep theirs
    again = np.zeros_like(parts)
    again[z] = 0.003
    model.take_parts(again, [64] * 6, [64] * 4 + [128, 64], irr)
    assert model.part_ratios[z] == pytest.approx(TAIL_RATIO_RANGE[0]) and model.part_ratios[0] == 0.5
    assert model.estimate_faces([64, 64, 64, 64, 128, 64]) == pytest.approx(0.001 + 0.003 * tail(0.35, 1))


def test_per_face_bake_meets_the_tolerance_for_less(lamp_room):
    tol = 0.01
    auto = bake_probe(lamp_room, LAMP_AT, ProbeSettings(tolerance=tol, irradiance_size=8, max_face_size=512))
    sizes = auto.settings["face_sizes"]
    z = cubemap.FACE_NAMES.index("+Z")
    assert len(sizes) == 6 and sizes[z] == max(sizes) > 64 and min(sizes) == 64, sizes
    truth = bake_probe(lamp_room, LAMP_AT, ProbeSettings(face_size=512, irradiance_size=8))
    err = relative_rms(auto.irradiance, truth.irradiance)
    assert err <= tol, (sizes, err)
    est = auto.settings["tolerance_plan"]["estimated_error"]
    assert auto.settings["converged"] and est <= tol and est >= err  # the estimate is on the safe side
    assert sum(n * n for n in sizes) < 6 * max(sizes) ** 2  # fewer pixels than the uniform bake of that size
    n = auto.settings["face_size"]
    assert n == min(max(sizes), RADIANCE_OUT_MAX) and np.asarray(auto.radiance).shape == (6, n, n, 4)
    # the radiance written keeps the light: its mean over the sphere matches the fine render's
    w = cubemap.texel_solid_angles(n)[None, ..., None]
    w512 = cubemap.texel_solid_angles(512)[None, ..., None]
    np.testing.assert_allclose((np.asarray(auto.radiance)[..., :3] * w).sum((0, 1, 2)),
                               (np.asarray(truth.radiance)[..., :3] * w512).sum((0, 1, 2)), rtol=tol)


def test_a_smooth_sky_stays_uniform_and_coarse():
    sky = bake_probe(_shuffled(shell_scene(SkyGradient(), 6000, radius=5.0)), [0, 0, 0],
                     ProbeSettings(tolerance=0.01, irradiance_size=8))
    assert sky.settings["converged"] and max(sky.settings["face_sizes"]) <= 64
