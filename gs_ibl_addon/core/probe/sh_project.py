"""Spherical-harmonic projection of a radiance cube and SH irradiance (Ramamoorthi & Hanrahan 2001).

Basis: real, orthonormal SH with the Condon-Shortley phase, ordered l = 0.., m = -l..l. For l <= 3 this is
exactly ``core.sh.sh_basis`` (the 3DGS basis and signs), so one coefficient layout serves splats and probes;
here it is extended to any order by the associated-Legendre recurrence.

Projection: L_lm = sum over texels of L * Y_lm(texel centre) * exact texel solid angle.
Irradiance: E(n)/pi = sum_l (A_l / pi) * w_l * sum_m L_lm Y_lm(n), with the clamped-cosine coefficients
A_0 = pi, A_1 = 2pi/3, A_2 = pi/4, A_odd>1 = 0, A_even = 2pi (-1)^(l/2-1) / ((l+2)(l-1)) * l! / (2^l (l/2)!^2),
and an optional window w_l against ringing (Sloan, "Stupid SH tricks"): none, hanning or lanczos.
Negative results (ringing behind a bright source) are clamped to 0 after evaluation.

Measured for order 2 (kernel of a point light, in units of its peak-normalised clamped cosine): no window
dips to -0.158/4pi (at cos = -0.53 from the light); Hanning dips least at width 5 (-0.076, but the rms error
of the kernel doubles, 0.26 vs 0.13); width 3 (= order+1) is *worse* than none (-0.19), because it damps band 2,
which cancels band 1's negative side. Hence the default width 2*order+1, and window "none" by default.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from .. import cubemap
from ..sh import coeff_count, degree_of
from .sampling import split_alpha

MAX_ORDER = 8  # beyond this a probe's irradiance gains nothing (A_l < 0.3% of A_0) and the recurrence loses digits


def sh_basis_any(dirs: np.ndarray, order: int) -> np.ndarray:
    """(..., 3) unit directions -> (..., (order+1)^2) real orthonormal SH values (CS phase; = core.sh for l<=3)."""
    if not 0 <= order <= MAX_ORDER:
        raise ValueError(f"SH order must be in 0..{MAX_ORDER}, got {order}")
    d = np.asarray(dirs, np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    out = [None] * coeff_count(order)
    # (x + i y)^m gives cos(m phi) sin^m(theta) and sin(m phi) sin^m(theta) without trigonometry.
    cm = [np.ones_like(x)]
    sm = [np.zeros_like(x)]
    for _ in range(order):
        cm.append(cm[-1] * x - sm[-1] * y)
        sm.append(cm[-2] * y + sm[-1] * x)
    for m in range(order + 1):
        # Q_l^m(z) = P_l^m(z) / sin^m(theta), P with the Condon-Shortley phase.
        q_mm = np.full_like(z, (-1.0) ** m * _double_factorial(2 * m - 1))
        q_prev, q = None, q_mm
        for l in range(m, order + 1):
            if l == m + 1:
                q_prev, q = q, z * (2 * m + 1) * q_mm
            elif l > m + 1:
                q_prev, q = q, ((2 * l - 1) * z * q - (l + m - 1) * q_prev) / (l - m)
            k = math.sqrt((2 * l + 1) / (4 * math.pi) * math.factorial(l - m) / math.factorial(l + m))
            if m == 0:
                out[l * l + l] = k * q
            else:
                out[l * l + l + m] = math.sqrt(2.0) * k * q * cm[m]
                out[l * l + l - m] = math.sqrt(2.0) * k * q * sm[m]
    return np.stack(out, -1)


def _double_factorial(n: int) -> int:
    return 1 if n <= 0 else n * _double_factorial(n - 2)


def cosine_lobe_coefficients(order: int) -> np.ndarray:
    """A_l, l = 0..order: the clamped-cosine kernel's zonal coefficients (so E_lm = A_l L_lm)."""
    a = np.zeros(order + 1)
    for l in range(order + 1):
        if l == 0:
            a[l] = math.pi
        elif l == 1:
            a[l] = 2.0 * math.pi / 3.0
        elif l % 2 == 0:
            a[l] = (2.0 * math.pi * (-1.0) ** (l // 2 - 1) / ((l + 2) * (l - 1))
                    * math.factorial(l) / (2.0 ** l * math.factorial(l // 2) ** 2))
    return a


WINDOWS = ("none", "hanning", "lanczos")


def window_factors(order: int, window: str = "none", width: float | None = None) -> np.ndarray:
    """Per-band factors w_l (l = 0..order); width defaults to 2*order + 1 (see the module notes)."""
    if window not in WINDOWS:
        raise ValueError(f"SH window must be one of {WINDOWS}, got {window!r}")
    l = np.arange(order + 1, dtype=np.float64)
    w = float(2 * order + 1 if width is None else width)
    if window == "none":
        return np.ones(order + 1)
    if window == "hanning":
        return np.where(l < w, 0.5 * (1.0 + np.cos(np.pi * l / w)), 0.0)
    return np.where(l < w, np.sinc(l / w), 0.0)  # lanczos: np.sinc is sin(pi x)/(pi x)


def project_cube(cube: np.ndarray, order: int = 2) -> np.ndarray:
    """SH coefficients ((order+1)^2, C) of a radiance cube (alpha, if any, is dropped: holes are black)."""
    rgb, _ = split_alpha(cube)
    n = rgb.shape[1]
    basis = face_basis(n, order)  # (6, N, N, K)
    w = cubemap.texel_solid_angles(n)[None, :, :, None]
    return np.einsum("fijk,fijc->kc", basis * w, rgb)


def sh_irradiance(coeffs: np.ndarray, dirs: np.ndarray, window: str = "none",
                  window_width: float | None = None, clamp: bool = True) -> np.ndarray:
    """E(n)/pi along (..., 3) unit normals from radiance SH coefficients (K, C) -> (..., C)."""
    return _irradiance(sh_basis_any(dirs, degree_of(coeffs.shape[0])), coeffs, window, window_width, clamp)


def sh_irradiance_faces(coeffs: np.ndarray, size: int, window: str = "none", window_width: float | None = None,
                        clamp: bool = True) -> np.ndarray:
    """sh_irradiance at every texel centre of a ``size``^2 cube, (6, size, size, C), on face_basis."""
    return _irradiance(face_basis(size, degree_of(coeffs.shape[0])), coeffs, window, window_width, clamp)


@functools.lru_cache(maxsize=16)
def face_basis(size: int, order: int) -> np.ndarray:
    """(6, size, size, (order+1)^2) read-only: sh_basis_any at every texel centre of a ``size``^2 cube. A bake
    evaluated it anew for every probe (0.2-0.8 ms of host time a bake at 16^2-32^2; issue 38)."""
    out = sh_basis_any(cubemap.face_directions(size), order)
    out.flags.writeable = False
    return out


def _irradiance(basis: np.ndarray, coeffs: np.ndarray, window: str, window_width: float | None,
                clamp: bool) -> np.ndarray:
    order = degree_of(coeffs.shape[0])
    band = np.repeat(cosine_lobe_coefficients(order) / math.pi * window_factors(order, window, window_width),
                     [2 * l + 1 for l in range(order + 1)])
    e = np.einsum("...k,kc->...c", basis, coeffs * band[:, None])
    return np.maximum(e, 0.0) if clamp else e


def sh_irradiance_cube(cube: np.ndarray, size: int, order: int = 2, window: str = "none",
                       window_width: float | None = None, clamp: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Radiance cube -> (irradiance cube (6, size, size, C) of E/pi, SH coefficients ((order+1)^2, C))."""
    coeffs = project_cube(cube, order)
    irr = sh_irradiance_faces(coeffs, size, window, window_width, clamp)
    return irr, coeffs
