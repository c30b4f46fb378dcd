"""core/sh_rotation.py: rotated SH evaluate toward R d as the original did toward d (checked by evaluating the basis,
not against another derivation of the rotation matrices)."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.sh import eval_sh_color, sh_basis
from gs_ibl_addon.core.sh_rotation import rotate_sh, sh_rotation_matrices


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_rotated_sh_evaluate_at_rotated_directions(degree):
    rng = np.random.default_rng(degree)
    k = (degree + 1) ** 2
    sh = rng.normal(scale=0.3, size=(50, k, 3)).astype(np.float32)
    dirs = rng.normal(size=(50, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for _ in range(5):
        r = _random_rotation(rng)
        rotated = rotate_sh(sh, r)
        np.testing.assert_array_equal(rotated[:, 0], sh[:, 0])  # the DC colour does not depend on direction
        # unclamped values: SH(d) + 0.5 before max(., 0), the quantity that rotates
        want = np.einsum("nk,nkc->nc", sh_basis(dirs, degree), sh.astype(np.float64))
        got = np.einsum("nk,nkc->nc", sh_basis(dirs @ r.T, degree), rotated.astype(np.float64))
        np.testing.assert_allclose(got, want, atol=2e-6)
        np.testing.assert_allclose(eval_sh_color(rotated, dirs @ r.T), eval_sh_color(sh, dirs), atol=2e-6)


def test_band_matrices_are_orthogonal_and_compose():
    rng = np.random.default_rng(7)
    a, b = _random_rotation(rng), _random_rotation(rng)
    for ma, mb, mab in zip(sh_rotation_matrices(a, 3), sh_rotation_matrices(b, 3), sh_rotation_matrices(a @ b, 3)):
        np.testing.assert_allclose(ma @ ma.T, np.identity(len(ma)), atol=1e-10)
        np.testing.assert_allclose(ma @ mb, mab, atol=1e-10)  # rotating by b then a = rotating by a b


def test_degree_0_and_identity_unchanged_and_bad_matrix_refused():
    sh = np.random.default_rng(1).normal(size=(4, 16, 3)).astype(np.float32)
    np.testing.assert_array_equal(rotate_sh(sh, np.identity(3)), sh)
    np.testing.assert_array_equal(rotate_sh(sh[:, :1], _random_rotation(np.random.default_rng(2))), sh[:, :1])
    with pytest.raises(ValueError, match="proper rotation"):
        rotate_sh(sh, np.diag([1.0, 1.0, -1.0]))  # a mirror
    with pytest.raises(ValueError, match="proper rotation"):
        rotate_sh(sh, 2.0 * np.identity(3))  # a scale


def test_quarter_turn_moves_band_1_like_a_vector():
    # band 1 is (-y, z, -x) * C1: a colour brighter toward +X, turned 90 degrees about Z, is brighter toward +Y
    sh = np.zeros((1, 4, 3), np.float32)
    sh[0, 3] = -1.0  # + x
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    out = rotate_sh(sh, rz)
    np.testing.assert_allclose(out[0, 1:], [[-1.0] * 3, [0.0] * 3, [0.0] * 3], atol=1e-6)  # -(-y) = + y
