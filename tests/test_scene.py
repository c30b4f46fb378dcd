"""SplatScene: moving splats by an object transform, and the degree-0 colour rule both ways."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.scene import SplatScene, quat_to_matrix, rgb_to_sh_dc, sh_dc_to_rgb
from gs_ibl_addon.core.sh import C0, coeff_count, degree_of, eval_sh_color
from gs_ibl_addon.core.synthetic import random_scene


def rotation(axis, degrees: float) -> np.ndarray:
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def matrix(linear: np.ndarray, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = linear
    m[:3, 3] = translation
    return m


def covariances(s: SplatScene) -> np.ndarray:
    r = quat_to_matrix(s.rotations)
    return r @ (s.scales.astype(np.float64)[:, :, None] ** 2 * np.transpose(r, (0, 2, 1)))


def test_rotation_uniform_scale_and_translation():
    scene = random_scene(200, seed=1, sh_degree=1)
    r = rotation((1.0, -2.0, 0.5), 37.0)
    t = np.array([0.3, -1.2, 4.0])
    out = scene.transformed(matrix(2.5 * r, t))
    np.testing.assert_allclose(out.positions, scene.positions.astype(np.float64) @ (2.5 * r).T + t, atol=1e-5)
    np.testing.assert_allclose(out.scales, 2.5 * scene.scales, rtol=1e-6)
    # Each splat's frame turns with the object: R_out = R R_in, so its covariance is (sR) C (sR)^T.
    np.testing.assert_allclose(quat_to_matrix(out.rotations), r @ quat_to_matrix(scene.rotations), atol=1e-6)
    want = (2.5 * r) @ covariances(scene) @ (2.5 * r).T
    np.testing.assert_allclose(covariances(out), want, rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(out.rotations, axis=1), 1.0, atol=1e-6)
    assert out.opacities is scene.opacities
    # View-dependent colour turns too: each splat shows toward R d what it showed toward d.
    d = np.random.default_rng(3).normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(eval_sh_color(out.sh, d @ r.T), eval_sh_color(scene.sh, d), atol=2e-5)


def test_translation_and_scale_keep_the_sh_arrays():
    scene = random_scene(20, seed=6, sh_degree=2)
    out = scene.transformed(matrix(3.0 * np.identity(3), np.array([1.0, 2.0, 3.0])))
    assert out.sh is scene.sh  # nothing turned: no copy of the (large) SH


def test_noise_of_a_float32_matrix_is_still_uniform():
    r = rotation((0.0, 0.0, 1.0), 90.0)
    noisy = (r * np.array([1.0, 1.0 + 2e-5, 1.0])).astype(np.float32)  # well inside the 1e-4 tolerance
    out = random_scene(10, seed=2).transformed(matrix(noisy))
    assert np.isfinite(out.scales).all()


@pytest.mark.parametrize("linear,factors", [
    (np.diag([1.0, 2.0, 1.0]), "1, 2, 1"),
    (rotation((1.0, 1.0, 0.0), 30.0) @ np.diag([0.5, 0.5, 1.5]), "0.5, 0.5, 1.5"),
    (np.diag([1.0, 1.0, 1.001]), "1, 1, 1.001"),  # just past the tolerance
])
def test_non_uniform_scale_is_refused(linear, factors):
    scene = random_scene(10, seed=3)
    with pytest.raises(ValueError) as info:
        scene.transformed(matrix(linear))
    msg = str(info.value)
    assert msg.startswith(f"{scene.source}: the transform scales non-uniformly (x, y, z factors {factors})"), msg
    assert "rotation, translation and uniform scale only" in msg and "same scale on all three axes" in msg


@pytest.mark.parametrize("linear", [np.diag([-1.0, 1.0, 1.0]), 2.0 * rotation((0, 1, 0), 10) @ np.diag([1, 1, -1])])
def test_mirror_is_refused(linear):
    with pytest.raises(ValueError, match=r"the transform mirrors .*uniform scale only: give the object the same scale on all three axes"):
        random_scene(10, seed=4).transformed(matrix(linear))


def test_degenerate_transform_is_refused():
    with pytest.raises(ValueError, match="degenerate"):
        random_scene(10, seed=5).transformed(matrix(np.diag([1.0, 1.0, 0.0])))
    with pytest.raises(ValueError, match="NaN"):
        random_scene(10, seed=5).transformed(matrix(np.full((3, 3), np.nan)))


def test_dc_colour_rule_both_ways():
    rgb = np.random.default_rng(6).uniform(-0.1, 1.1, (50, 3)).astype(np.float32)
    dc = rgb_to_sh_dc(rgb)
    assert dc.dtype == np.float32
    np.testing.assert_allclose(sh_dc_to_rgb(dc), rgb, atol=1e-6)
    np.testing.assert_allclose(sh_dc_to_rgb(np.ones(1)), 0.5 + C0)


def test_sh_counts():
    assert [coeff_count(d) for d in range(4)] == [1, 4, 9, 16]
    assert [degree_of(k) for k in (1, 4, 9, 16, 81)] == [0, 1, 2, 3, 8]
    for bad in (0, 5, 15):
        with pytest.raises(ValueError, match="not a square"):
            degree_of(bad)
    assert random_scene(3, sh_degree=2).sh_degree == 2
