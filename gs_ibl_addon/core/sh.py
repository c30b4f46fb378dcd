"""Real spherical harmonics in the 3DGS convention (degree <= 3): basis values and colour evaluation.

One basis serves the splat colours (as trained by 3DGS) and any filter that wants the same ordering.
The basis is orthonormal over the sphere; the signs follow the 3DGS reference implementation so that
trained f_rest coefficients evaluate as they were trained.
"""
from __future__ import annotations

import numpy as np

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def coeff_count(degree: int) -> int:
    """SH coefficients per colour channel up to ``degree``: (degree + 1)^2."""
    return (degree + 1) ** 2


def degree_of(count: int) -> int:
    """The SH degree whose coefficient count is ``count``; ValueError if ``count`` is not a square."""
    degree = int(round(float(np.sqrt(count)))) - 1
    if degree < 0 or coeff_count(degree) != count:
        raise ValueError(f"SH coefficient count {count} is not a square (degree+1)^2")
    return degree


def sh_basis(dirs: np.ndarray, degree: int) -> np.ndarray:
    """(..., 3) unit directions -> (..., (degree+1)^2) basis values, 3DGS order and signs."""
    d = np.asarray(dirs, np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    out = [np.full(x.shape, C0)]
    if degree >= 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]
    if degree >= 3:
        out += [C3[0] * y * (3 * xx - yy), C3[1] * xy * z, C3[2] * y * (4 * zz - xx - yy),
                C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy),
                C3[5] * z * (xx - yy), C3[6] * x * (xx - 3 * yy)]
    if degree > 3:
        raise ValueError(f"SH degree {degree} > 3 is not supported")
    return np.stack(out, -1)


def eval_sh_color(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """3DGS colour: sh (N, K, 3), dirs (N, 3) unit, from the viewer toward the splat -> (N, 3) >= 0."""
    basis = sh_basis(dirs, degree_of(sh.shape[1]))  # (N, K)
    rgb = np.einsum("nk,nkc->nc", basis, sh.astype(np.float64)) + 0.5
    return np.maximum(rgb, 0.0)
