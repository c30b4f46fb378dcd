"""SH irradiance at many points: probes baked at given positions, a regular grid of them (an irradiance volume),
its trilinear interpolation, and the float image a shader reads it from.

A probe here is its order-2 radiance SH (9 RGB coefficients), enough for diffuse light. For shaders the SH
are folded with the cosine lobe and the basis constants into coefficients of nine polynomials of the normal,
``MONOMIALS`` (1, y, z, x, xy, yz, 3z^2 - 1, xz, x^2 - y^2), so E(n)/pi = sum_k d_k P_k(n): a shader evaluates
that with a few multiplies and no table.

The grid image (``pack_grid``): width 9 nx, height nz ny; coefficient k of node (ix, iy, iz) sits at column
k nx + ix, row iz ny + iy (row 0 = the bottom row, as Blender stores images). A lookup at texel centres with
bilinear filtering then interpolates x and y inside one coefficient's tile and never reaches the next tile;
z is blended by hand between two slices (``sample_packed``, the numpy twin of the shader).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .sh_project import cosine_lobe_coefficients

ORDER = 2
COEFFS = 9
# the polynomial each 3DGS-order SH basis function of l <= 2 is a constant times (on unit vectors, 2z^2 - x^2 - y^2
# = 3z^2 - 1), and that constant
MONOMIALS = ("1", "y", "z", "x", "xy", "yz", "3zz-1", "xz", "xx-yy")
_BASIS_CONSTANTS = np.array([0.28209479177387814, -0.4886025119029199, 0.4886025119029199, -0.4886025119029199,
                             1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                             0.5462742152960396])
# Many cheap probes (grids, per-object probes, Lighting Auto's measurements): 64^2. Faces read the radiance at their
# texel centres (render/splat_math.py), and at 32^2 where a lamp falls between centres moves with the probe: 10 cm
# at the sample room's probe read 13% of light variation at 32^2, 3.4% at 64^2, 2.7% at 128^2 and 256^2; a 5 cm
# path's steps were 1.8x their median at 32^2, 1.04x at 64^2 (2026-12-03).
POINT_FACE_SIZE = 64


def monomial_coefficients(sh: np.ndarray) -> np.ndarray:
    """Radiance SH (..., 9, C) -> d (..., 9, C) with E(n)/pi = sum_k d_k P_k(n) (P_k: ``MONOMIALS``)."""
    sh = np.asarray(sh, np.float64)
    if sh.shape[-2] != COEFFS:
        raise ValueError(f"order-2 SH has 9 coefficients per channel, got {sh.shape[-2]}")
    band = np.repeat(cosine_lobe_coefficients(ORDER) / math.pi, [1, 3, 5])
    return sh * (band * _BASIS_CONSTANTS)[:, None]


def monomials(normals: np.ndarray) -> np.ndarray:
    """(..., 3) unit normals -> (..., 9) values of ``MONOMIALS``."""
    n = np.asarray(normals, np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([np.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y], -1)


def eval_irradiance(d: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """E(n)/pi from monomial coefficients: d (..., 9, C) and normals (..., 3) of the same leading shape (or d
    without one: (9, C)) -> (..., C). Not clamped: differences of probes are signed."""
    return np.einsum("...k,...kc->...c", monomials(normals), np.asarray(d, np.float64))


@dataclass(frozen=True)
class GridSpec:
    """nx x ny x nz probes spanning the box lo..hi (a single probe along an axis sits at the box's middle)."""
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lo, np.float64), np.asarray(self.hi, np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError(f"grid box {self.lo} .. {self.hi} must be two points of three finite numbers")
        if np.any(hi < lo):
            raise ValueError(f"grid box {self.lo} .. {self.hi}: every 'hi' coordinate must be >= its 'lo'")
        if len(self.shape) != 3 or any(int(n) != n or n < 1 or n > 64 for n in self.shape):
            raise ValueError(f"grid resolution {tuple(self.shape)} must be three whole numbers from 1 to 64")

    @property
    def count(self) -> int:
        return int(np.prod(self.shape))

    def axis_points(self, axis: int) -> np.ndarray:
        n, lo, hi = self.shape[axis], self.lo[axis], self.hi[axis]
        return np.array([(lo + hi) / 2]) if n == 1 else np.linspace(lo, hi, n)

    def points(self) -> np.ndarray:
        """(nx, ny, nz, 3) probe positions."""
        return np.stack(np.meshgrid(*(self.axis_points(a) for a in range(3)), indexing="ij"), -1)

    def grid_coords(self, positions: np.ndarray) -> np.ndarray:
        """(..., 3) world positions -> (..., 3) continuous node coordinates, clamped to the grid (outside the box a
        point takes the nearest face's light)."""
        p = np.asarray(positions, np.float64)
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        n = np.asarray(self.shape, np.float64)
        span = np.where(hi > lo, hi - lo, 1.0)
        return np.clip((p - lo) / span * (n - 1), 0.0, n - 1)


def interpolate(values: np.ndarray, spec: GridSpec, positions: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of per-node values (nx, ny, nz, ...) at world positions (M, 3) -> (M, ...)."""
    v = np.asarray(values, np.float64)
    g = spec.grid_coords(positions)
    i0 = np.minimum(np.floor(g).astype(int), np.asarray(spec.shape) - 1)
    i1 = np.minimum(i0 + 1, np.asarray(spec.shape) - 1)
    f = g - i0
    out = 0.0
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                w = ((f[:, 0] if cx else 1 - f[:, 0]) * (f[:, 1] if cy else 1 - f[:, 1])
                     * (f[:, 2] if cz else 1 - f[:, 2]))
                idx = tuple(np.where(c, i1[:, a], i0[:, a]) for a, c in enumerate((cx, cy, cz)))
                out = out + w.reshape(-1, *([1] * (v.ndim - 3))) * v[idx]
    return out


def pack_grid(d: np.ndarray) -> np.ndarray:
    """Monomial coefficients per node (nx, ny, nz, 9, 3) -> the grid image (nz ny, 9 nx, 3), row 0 at the bottom."""
    d = np.asarray(d, np.float32)
    nx, ny, nz = d.shape[:3]
    # image[iz*ny + iy, k*nx + ix] = d[ix, iy, iz, k]
    return d.transpose(2, 1, 3, 0, 4).reshape(nz * ny, COEFFS * nx, 3)


def _bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A texture unit's bilinear lookup (texel centres at (i + 0.5) / size, clamped at the edges); row 0 at v = 0."""
    h, w = image.shape[:2]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    return ((1 - fy) * ((1 - fx) * image[ya, xa] + fx * image[ya, xb])
            + fy * ((1 - fx) * image[yb, xa] + fx * image[yb, xb]))


def sample_packed(image: np.ndarray, spec: GridSpec, positions: np.ndarray) -> np.ndarray:
    """What the shader does with the grid image: (M, 3) positions -> (M, 9, 3) interpolated coefficients.

    Per coefficient two bilinear lookups (the z slices below and above the point) blended by the z fraction."""
    nx, ny, nz = spec.shape
    h, w = image.shape[:2]
    g = spec.grid_coords(positions)
    z0 = np.minimum(np.floor(g[:, 2]), nz - 1)
    z1 = np.minimum(z0 + 1, nz - 1)
    fz = (g[:, 2] - z0)[:, None]
    out = np.empty((len(g), COEFFS, image.shape[2]))
    for k in range(COEFFS):
        u = (k * nx + g[:, 0] + 0.5) / w
        lower = _bilinear(image, u, (z0 * ny + g[:, 1] + 0.5) / h)
        upper = _bilinear(image, u, (z1 * ny + g[:, 1] + 0.5) / h)
        out[:, k] = (1 - fz) * lower + fz * upper
    return out


def bake_sh_points(renderer, positions: np.ndarray, face_size: int = POINT_FACE_SIZE,
                   progress: Callable[[int, int], None] | None = None, **settings) -> np.ndarray:
    """Order-2 radiance SH (P, 9, 3) of probes at (P, 3) world positions, rendered by ``renderer`` (a
    SplatRenderer holding the splats in world space) with ``face_size``^2 faces; ``settings``: further
    ProbeSettings (hole_fill, ...).

    Batched (core.bake_batch.bake_probes: one render and one filter submission per chunk), in chunks as large as
    the device holds at this face size; each probe is what bake_probe gives at its position."""
    from ..bake import ProbeSettings
    from ..bake_batch import bake_probes
    from ..render.renderer import largest_probe_face
    pts = np.asarray(positions, np.float64).reshape(-1, 3)
    s = ProbeSettings(method="sh", face_size=int(face_size), irradiance_size=4, sh_order=ORDER, **settings)
    chunk = max(1, len(pts))
    while chunk > 1 and largest_probe_face(renderer.ctx, chunk) < face_size:
        chunk = (chunk + 1) // 2
    out = np.empty((len(pts), COEFFS, 3))
    for start in range(0, len(pts), chunk):
        part = bake_probes(None, pts[start:start + chunk], s, renderer=renderer, keep_radiance=False)
        out[start:start + len(part)] = [np.asarray(p.sh_coefficients)[:COEFFS, :3] for p in part]
        if progress is not None:
            progress(start + len(part), len(pts))
    return out


def bake_grid(renderer, spec: GridSpec, face_size: int = POINT_FACE_SIZE,
              progress: Callable[[int, int], None] | None = None, **settings) -> np.ndarray:
    """Radiance SH (nx, ny, nz, 9, 3) at every node of ``spec``."""
    sh = bake_sh_points(renderer, spec.points().reshape(-1, 3), face_size, progress, **settings)
    return sh.reshape(*spec.shape, COEFFS, 3)
