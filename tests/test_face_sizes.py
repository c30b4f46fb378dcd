"""Face size 0 sizes each cube face by itself (core/bake.py choose_face_sizes): a small bright light's face is
rendered finer, the rest stay coarse, and the irradiance still meets the tolerance against a fine uniform render."""
import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.bake import RADIANCE_OUT_MAX, ProbeSettings, bake_probe, relative_rms
from gs_ibl_addon.core.probe.box import downsample_cube, faces_to_size
from gs_ibl_addon.core.synthetic import BrightPatch, SkyGradient, shell_scene
from gs_ibl_addon.core.tolerance import ErrorModel, footprints

SUN = BrightPatch()  # its disc lies in the +Z face


def _shuffled(scene, seed=3):
    order = np.random.default_rng(seed).permutation(scene.count)
    return scene.subset(order)


@pytest.fixture(scope="module")
def sun_shell():
    return _shuffled(shell_scene(SUN, 8000, radius=5.0))


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


def test_face_excess_adds_up_to_the_uniform_excess(sun_shell):
    prints = footprints(sun_shell, np.zeros(3))
    for n in (32, 64, 256):
        assert np.sum(prints.face_excess([n] * 6)) == pytest.approx(prints.excess(n), rel=1e-9)
    assert np.sum(prints.face_light()) == pytest.approx(1.0)
    assert int(np.argmax(prints.face_light())) == cubemap.FACE_NAMES.index("+Z")  # the sun's face


def test_the_plan_refines_the_bright_face_first(sun_shell):
    model = ErrorModel(footprints(sun_shell, np.zeros(3)))
    model.calibrate(32, 64, 0.05)  # as if 32^2 -> 64^2 had moved the irradiance by 5%
    sizes, est = model.plan_faces(0.01, 64, 1024)
    z = cubemap.FACE_NAMES.index("+Z")
    assert est <= 0.01 and sizes[z] == max(sizes) and sizes[z] > 64
    assert min(sizes) < sizes[z]  # the dim faces are not all made as fine
    assert est == pytest.approx(model.estimate_faces(sizes, 64))


def test_per_face_bake_meets_the_tolerance_for_less(sun_shell):
    tol = 0.01
    auto = bake_probe(sun_shell, [0, 0, 0], ProbeSettings(tolerance=tol, irradiance_size=8, max_face_size=512))
    sizes = auto.settings["face_sizes"]
    z = cubemap.FACE_NAMES.index("+Z")
    assert len(sizes) == 6 and sizes[z] == max(sizes)
    truth = bake_probe(sun_shell, [0, 0, 0], ProbeSettings(face_size=512, irradiance_size=8))
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
