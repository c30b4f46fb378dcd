"""Irradiance filters (cosine convolution, box, exact) and GGX prefiltering against exact references.

Synthetic cubes are sampled from analytic radiance functions at texel centres (reference.cube_from_function).
"""
import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.bake import relative_rms
from gs_ibl_addon.core.probe import (box_irradiance, cosine_convolve, downsample_cube, exact_irradiance_cube,
                                     ggx_prefilter, sample_cube_bilinear, sh_irradiance_cube, split_alpha)
from gs_ibl_addon.core.probe.ggx import ggx_prefilter_level
from gs_ibl_addon.core.probe.box import halving_sizes, mip_chain
from gs_ibl_addon.core.probe.reference import (analytic_irradiance, bright_patch_environment, cube_from_function,
                                               exact_ggx_prefilter, integration_size, smooth_environment,
                                               smooth_environment_irradiance)


@pytest.fixture(scope="module")
def smooth_cube():
    return cube_from_function(smooth_environment, 64)


@pytest.fixture(scope="module")
def patch_cube():
    return cube_from_function(bright_patch_environment, 64)


METHODS = {
    "sh": lambda c, m: sh_irradiance_cube(c, m)[0],
    "convolve": lambda c, m: cosine_convolve(c, m, 32, 8),
    "box": lambda c, m: box_irradiance(c, m, 1),
    "box_thesis": lambda c, m: box_irradiance(c, m, m),
    "exact": exact_irradiance_cube,
    "ggx_r0.5": lambda c, m: ggx_prefilter(c, (0.5,), (m,), 64)[0],
}


@pytest.mark.parametrize("method", sorted(METHODS))
def test_uniform_environment_gives_its_radiance(method):
    # Brief: within 0.1% everywhere. Every filter is a normalised weighted mean except "exact", whose
    # cosine is taken at texel centres (measured 5e-5 at N=32): 0.1% holds for all.
    cube = np.full((6, 32, 32, 3), 2.5)
    np.testing.assert_allclose(METHODS[method](cube, 8), 2.5, rtol=1e-3)


def _rotate_z90(fn):
    # Environment turned by +90 degrees about Z: L'(d) = L(R^T d), R^T (x, y, z) = (y, -x, z).
    return lambda d: fn(np.stack([d[..., 1], -d[..., 0], d[..., 2]], -1))


@pytest.mark.parametrize("method", sorted(METHODS))
def test_rotating_the_environment_rotates_the_map(method):
    # A 90-degree turn about Z maps cube texel centres onto texel centres (side faces cycle, +-Z turn in
    # place), so map'(d) must equal map(R^T d) texel for texel. Measured: 1e-15 for sh/box/exact; the
    # convolution and GGX tangent frames (helper axis Z) turn with the world too: 1e-15 as well.
    fn = lambda d: bright_patch_environment(d, radius_deg=20.0, bright=50.0) + smooth_environment(d)
    a = METHODS[method](cube_from_function(fn, 32), 8)
    b = METHODS[method](cube_from_function(_rotate_z90(fn), 32), 8)
    d = cubemap.face_directions(8)
    a_at_rotated = cubemap.sample_cube_nearest(a, np.stack([d[..., 1], -d[..., 0], d[..., 2]], -1))
    np.testing.assert_allclose(b, a_at_rotated, rtol=1e-9, atol=1e-12)
    assert not np.allclose(a, b)  # the environment is not symmetric: the test can fail


def test_exact_reference_matches_closed_form():
    # The per-texel integration of a 64^2 cube vs the closed form of a band-2 environment: the only error is
    # the cosine at texel centres (measured 1.6e-5 abs on values ~1): tolerance 1e-4.
    cube = cube_from_function(smooth_environment, 64)
    n = cubemap.face_directions(8)
    np.testing.assert_allclose(exact_irradiance_cube(cube, 8)[..., :2], smooth_environment_irradiance(n), atol=1e-4)
    np.testing.assert_allclose(analytic_irradiance(smooth_environment, n)[..., :2],
                               smooth_environment_irradiance(n), atol=1e-12)  # Gauss-Legendre: exact for polys


def test_convolution_converges_to_exact(smooth_cube):
    # Smooth environment: measured rel RMS 7.8e-3 (8x2 samples), 1.3e-3 (16x4), 8.8e-5 (64x16, M=16).
    ref = exact_irradiance_cube(smooth_cube, 8)
    assert relative_rms(cosine_convolve(smooth_cube, 8, 64, 16), ref) < 5e-4
    assert relative_rms(cosine_convolve(smooth_cube, 8, 16, 4), ref) < 3e-3


def test_convolution_noise_at_low_sample_counts(patch_cube):
    # Known weak spot: the regular (phi, theta) grid either misses or hits the 5-degree bright disc.
    # Measured rel RMS vs exact (M=8), reading the cube at 64^2: 8x2: 3.01, 16x4: 1.50, 64x16: 0.15; since the
    # convolution reads a copy downsampled to two texels per theta step (convolve.source_sizes, docs/stability.md):
    # 0.75, 0.71, 0.10.
    ref = exact_irradiance_cube(patch_cube, 8)
    errs = {s: relative_rms(cosine_convolve(patch_cube, 8, *s), ref) for s in ((8, 2), (16, 4), (64, 16))}
    assert errs[(8, 2)] > 0.5  # wrong by more than half the signal: unusable
    assert errs[(16, 4)] > 0.5
    assert errs[(64, 16)] < 0.3
    assert errs[(8, 2)] > errs[(16, 4)] > errs[(64, 16)]


def test_box_filter_error(smooth_cube, patch_cube):
    # Known weak spot: the thesis box filter averages radiance over a patch, not a cosine lobe. Measured rel
    # RMS vs exact on the smooth environment (M=16 output): level 16 (the thesis's 512->32 analogue) 15%,
    # 4: 14%, 2: 9.9%, 1: 4.5%; on the bright patch: 1173%, 395%, 148%, 60%. Bounds: measured +-15%.
    ref_s = exact_irradiance_cube(smooth_cube, 16)
    ref_p = exact_irradiance_cube(patch_cube, 16)
    measured_smooth = {16: 0.1535, 4: 0.1356, 2: 0.0986, 1: 0.0451}
    measured_patch = {16: 11.73, 4: 3.949, 2: 1.484, 1: 0.6036}
    for level, want in measured_smooth.items():
        assert relative_rms(box_irradiance(smooth_cube, 16, level), ref_s) == pytest.approx(want, rel=0.15)
    for level, want in measured_patch.items():
        assert relative_rms(box_irradiance(patch_cube, 16, level), ref_p) == pytest.approx(want, rel=0.15)


def test_halving_sizes_drive_every_downsampling_chain():
    assert halving_sizes(64, 16) == [64, 32, 16]
    assert halving_sizes(12) == [12, 6, 3] and halving_sizes(8, 8) == [8] and halving_sizes(5) == [5]
    assert [m.shape[1] for m in mip_chain(np.ones((6, 12, 12, 3)))] == [12, 6, 3]
    # downsample_to halves while above the target and even, so it can land below the target (48 -> 24 -> 12).
    assert [integration_size(48, d) for d in (16, 12, 48, None)] == [12, 12, 48, 48]
    assert integration_size(36, 16) == 9


def test_downsample_preserves_radiant_power(patch_cube):
    # Solid-angle weighting: sum L dOmega (the total power) is the same at every mip (to float rounding).
    total = lambda c: np.sum(c * cubemap.texel_solid_angles(c.shape[1])[None, :, :, None])
    t0 = total(patch_cube)
    for m in mip_chain(patch_cube)[1:]:
        assert total(m) == pytest.approx(t0, rel=1e-12)
    with pytest.raises(ValueError, match="odd"):
        downsample_cube(np.ones((6, 3, 3, 3)))


@pytest.mark.parametrize("n", [1, 2, 3, 8, 32])
def test_bilinear_lookup_is_continuous_across_edges_and_corners(n):
    # Random cube; directions a hair (1e-9) to either side of the +X/+Y edge and around the +X+Y+Z corner
    # read from different faces but must agree: measured differences <= 2.5e-8 (N=32): tolerance 1e-6.
    # (Clamping at face edges, the non-seamless way, differs by O(texel contrast) ~ 0.5 here.)
    cube = np.random.default_rng(n).random((6, n, n, 3))
    z = np.linspace(-0.999, 0.999, 41)
    on_edge = np.stack([np.ones_like(z), np.ones_like(z), z], -1)
    a = sample_cube_bilinear(cube, on_edge + [1e-9, 0, 0])
    b = sample_cube_bilinear(cube, on_edge + [0, 1e-9, 0])
    np.testing.assert_allclose(a, b, atol=1e-6)
    corner = [sample_cube_bilinear(cube, np.array([[1.0, 1.0, 1.0]]) + p) for p in np.eye(3) * 1e-9]
    np.testing.assert_allclose(corner[0], corner[1], atol=1e-6)
    np.testing.assert_allclose(corner[0], corner[2], atol=1e-6)


def test_bilinear_lookup_reproduces_texels_and_smooth_functions():
    cube = cube_from_function(smooth_environment, 16)
    d = cubemap.face_directions(16)
    np.testing.assert_allclose(sample_cube_bilinear(cube, d), cube, rtol=1e-12)
    q = np.random.default_rng(3).normal(size=(500, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    # Interpolation error of a smooth function at N=16: measured max 0.011 on values 0.2..2.5.
    np.testing.assert_allclose(sample_cube_bilinear(cube, q), smooth_environment(q), atol=0.02)


def test_ggx_matches_exact_lobe_on_smooth_environment(smooth_cube):
    # The estimator converges to exact_ggx_prefilter. Filtered importance sampling (lod bias 1) blurs a little:
    # measured rel RMS at 256 samples: r=0.25: 0.24%, 0.5: 0.34%, 1.0: 0.92%. Tolerance: 1.5x measured.
    mips = mip_chain(smooth_cube)
    n = cubemap.face_directions(8)
    for r, tol in ((0.25, 0.0036), (0.5, 0.0051), (1.0, 0.0138)):
        assert relative_rms(ggx_prefilter_level(mips, 8, r, 256), exact_ggx_prefilter(smooth_cube, n, r)) < tol


def test_ggx_mip_filtering_removes_fireflies(patch_cube):
    # Known weak spot of plain importance sampling: a small bright source aliases into fireflies. Measured rel
    # RMS at r=1.0 vs the exact lobe: 64 samples plain 258%, filtered 27%; 256 plain 93%, filtered 10%.
    mips = mip_chain(patch_cube)
    ref = exact_ggx_prefilter(patch_cube, cubemap.face_directions(8), 1.0)
    plain = relative_rms(ggx_prefilter_level(mips, 8, 1.0, 64, lod_bias=-100.0), ref)  # lod clamps to 0: no filtering
    filtered = relative_rms(ggx_prefilter_level(mips, 8, 1.0, 64), ref)
    assert plain > 2.0 and filtered < 0.35


def test_ggx_roughness_zero_is_the_radiance(smooth_cube):
    out = ggx_prefilter(smooth_cube, (0.0,), (64,))[0]
    np.testing.assert_allclose(out, smooth_cube, rtol=1e-12)  # bilinear at texel centres returns the texel


def test_holes_are_black_and_reported():
    # -Z face has no splats (alpha 0): radiance there counts as black and the hole fraction is 1/6 exactly
    # (each face has solid angle 4pi/6).
    cube = np.ones((6, 16, 16, 4))
    cube[5] = 0.0
    rgb, hole = split_alpha(cube)
    assert hole == pytest.approx(1 / 6, rel=1e-12)
    irr = exact_irradiance_cube(cube, 8)
    assert irr.shape == (6, 8, 8, 3)
    # Facing +Z (central texels, within 10 degrees of the axis): the hemisphere holds no -Z face direction.
    np.testing.assert_allclose(irr[4, 3:5, 3:5], 1.0, rtol=1e-3)
    # Facing -Z: the hole covers the middle of the hemisphere; compare with the quadrature of the same
    # function (1 off the -Z face, 0 on it). Measured 0.45458 vs 0.45467 (2e-4); the discontinuity makes
    # both converge slowly: tolerance 1%.
    fn = lambda d: np.repeat((cubemap.direction_to_face(d)[0] != 5)[..., None], 3, -1).astype(float)
    want = analytic_irradiance(fn, cubemap.face_directions(8)[5, 3:5, 3:5], 128, 256)
    np.testing.assert_allclose(irr[5, 3:5, 3:5], want, rtol=0.01)
    assert irr[5, 3:5, 3:5].max() < 0.7

