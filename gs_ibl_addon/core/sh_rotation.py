"""Rotating splats' view-dependent colour (real SH bands 1-3, core/sh.py's 3DGS basis) with the splats.

A splat's colour toward d is SH(d) evaluated in the frame it was trained (or stored) in. Moved by a rotation R, the
splat must show toward R d what it showed toward d, so its coefficients become c' with SH'(d) = SH(R^T d). Each band
l is closed under rotation, so c'_l = M_l c_l with a (2l+1)^2 matrix per band, found here by least squares from the
basis at fixed sample directions: M_l = Y_l(D)^+ Y_l(R^T D). That needs only the basis the renderer itself evaluates
(sh_basis), so its order and sign conventions cannot drift from the renderer's.
"""
from __future__ import annotations

import numpy as np

from .sh import degree_of, sh_basis

# Enough well-spread directions that every band's basis matrix has full column rank (and good conditioning).
_SAMPLES = 64


def _sample_directions() -> np.ndarray:
    i = np.arange(_SAMPLES, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / _SAMPLES
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * (np.pi * (3.0 - np.sqrt(5.0)))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def sh_rotation_matrices(rotation: np.ndarray, degree: int) -> list[np.ndarray]:
    """Per band l = 1..degree, the (2l+1, 2l+1) matrix taking band-l coefficients of a function to those of the
    function rotated by the 3x3 ``rotation`` (a proper rotation: orthonormal, det +1)."""
    r = np.asarray(rotation, np.float64).reshape(3, 3)
    if not (np.allclose(r @ r.T, np.identity(3), atol=1e-5) and np.linalg.det(r) > 0):
        raise ValueError("SH rotation needs a proper rotation matrix (orthonormal, no mirror): "
                         "divide out the object's uniform scale first")
    d = _sample_directions()
    y = sh_basis(d, degree)
    y_rot = sh_basis(d @ r, degree)  # rows: Y(R^T d) (d @ r is (R^T d) as rows)
    mats = []
    for band in range(1, degree + 1):
        lo, hi = band * band, (band + 1) * (band + 1)
        m, *_ = np.linalg.lstsq(y[:, lo:hi], y_rot[:, lo:hi], rcond=None)
        mats.append(m)  # c' = m @ c  <=>  Y(d) . c' = Y(R^T d) . c for every d
    return mats


def rotate_sh(sh: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """SH coefficients (N, K, 3) (K = 1, 4, 9 or 16; band 0 first) of splats rotated by ``rotation``: the DC
    colour is unchanged, bands 1..3 are mixed within each band. Returns float32 (a copy; degree 0: the same
    values)."""
    sh = np.ascontiguousarray(sh, np.float32)
    degree = degree_of(sh.shape[1])
    if degree == 0 or np.allclose(rotation, np.identity(3), atol=1e-7):
        return sh.copy()
    n, k, _ = sh.shape
    block = np.identity(k)  # the bands' matrices on the diagonal; the DC row stays 1
    for band, m in enumerate(sh_rotation_matrices(rotation, degree), start=1):
        lo, hi = band * band, (band + 1) * (band + 1)
        block[lo:hi, lo:hi] = m
    # One GEMM over (coefficient, channel) pairs: each splat's K x 3 block is a row of the (N, 3K) view, so no
    # transposed copies (3M splats at degree 3: ~0.4 s, 5x the per-band tensordot).
    pairs = np.kron(block, np.identity(3)).astype(np.float32)
    return (sh.reshape(n, 3 * k) @ pairs.T).reshape(n, k, 3)
