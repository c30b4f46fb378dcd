"""Cube validation, alpha/hole handling and filtered lookups of a (6, N, N, C) cube along directions.

All direction maths goes through ``core.cubemap`` (direction_to_face, FACE_BASES); this module only adds
filtering. Bilinear lookups are *seamless*: a tap that falls off its face (within half a texel of an edge)
is replaced by the texel the extrapolated texel-centre direction lands on in the neighbouring face (at a
cube corner, the mean of the three texels that meet there), so a filtered cube has no face seams, as a Vulkan cube
sampler (always seamless) would give.
"""
from __future__ import annotations

import numpy as np

from .. import cubemap


def check_cube(cube: np.ndarray, name: str = "cube") -> np.ndarray:
    """Return the cube as float64 after checking it is (6, N, N, C) with C in (1, 3, 4) and finite."""
    a = np.asarray(cube)
    if a.ndim != 4 or a.shape[0] != 6 or a.shape[1] != a.shape[2] or a.shape[3] not in (1, 3, 4):
        raise ValueError(f"{name}: expected a cube shaped (6, N, N, C) with C in (1, 3, 4), got {a.shape}")
    if a.shape[1] < 1:
        raise ValueError(f"{name}: faces are empty (shape {a.shape})")
    a = a.astype(np.float64, copy=False)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains {int(np.count_nonzero(~np.isfinite(a)))} NaN/inf values; "
                         "check the renderer output before filtering")
    return a


def split_alpha(cube: np.ndarray) -> tuple[np.ndarray, float]:
    """(6,N,N,C) cube -> (premultiplied RGB cube, hole fraction of the sphere by solid angle).

    Alpha < 1 marks a hole (no splats in that direction). Radiance is kept premultiplied, i.e. holes
    contribute black: no light is invented for them; the hole fraction is reported so callers can warn.
    """
    a = check_cube(cube)
    if a.shape[3] != 4:
        return a, 0.0
    w = cubemap.texel_solid_angles(a.shape[1])
    alpha = np.clip(a[..., 3], 0.0, 1.0)
    hole = float(np.sum((1.0 - alpha) * w[None]) / (4.0 * np.pi))
    return a[..., :3], hole


def _texel_lookup(cube: np.ndarray, face: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    # Taps inside the face read directly; a tap off one edge follows its extrapolated texel-centre direction
    # into the neighbouring face. A tap off two edges (a cube corner, where only three texels meet) is the
    # mean of those three texels, so every face sharing the corner sees the same value there: lookups are
    # continuous across edges and corners, and rotating the cube rotates them exactly.
    n = cube.shape[1]
    i_in = (i >= 0) & (i < n)
    j_in = (j >= 0) & (j < n)
    out = np.empty(face.shape + cube.shape[3:], cube.dtype)
    inside = i_in & j_in
    out[inside] = cube[face[inside], j[inside], i[inside]]
    edge = i_in ^ j_in
    if np.any(edge):
        out[edge] = _neighbour(cube, face[edge], i[edge], j[edge])
    corner = ~(i_in | j_in)
    if np.any(corner):
        f, ic, jc = face[corner], i[corner], j[corner]
        icl, jcl = np.clip(ic, 0, n - 1), np.clip(jc, 0, n - 1)
        out[corner] = (cube[f, jcl, icl] + _neighbour(cube, f, ic, jcl) + _neighbour(cube, f, icl, jc)) / 3.0
    return out


def _neighbour(cube: np.ndarray, face: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    # Off-face texel (one coordinate outside 0..N-1): nearest texel along its extrapolated centre direction.
    n = cube.shape[1]
    s = 2.0 * (i + 0.5) / n - 1.0
    t = 2.0 * (j + 0.5) / n - 1.0
    b = cubemap.FACE_BASES[face]
    return cubemap.sample_cube_nearest(cube, b[:, 0] + s[:, None] * b[:, 1] + t[:, None] * b[:, 2])


def sample_cube_bilinear(cube: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Seamless bilinear lookup of a (6, N, N, C) cube along (..., 3) directions -> (..., C)."""
    n = cube.shape[1]
    shape = dirs.shape[:-1]
    d = np.asarray(dirs, np.float64).reshape(-1, 3)
    face, s, t = cubemap.direction_to_face(d)
    x = (s + 1.0) * 0.5 * n - 0.5  # continuous texel coordinates, texel centres at integers
    y = (t + 1.0) * 0.5 * n - 0.5
    i0 = np.floor(x).astype(np.int64)
    j0 = np.floor(y).astype(np.int64)
    fx = (x - i0)[:, None]
    fy = (y - j0)[:, None]
    c00 = _texel_lookup(cube, face, i0, j0)
    c10 = _texel_lookup(cube, face, i0 + 1, j0)
    c01 = _texel_lookup(cube, face, i0, j0 + 1)
    c11 = _texel_lookup(cube, face, i0 + 1, j0 + 1)
    out = (c00 * (1 - fx) + c10 * fx) * (1 - fy) + (c01 * (1 - fx) + c11 * fx) * fy
    return out.reshape(shape + cube.shape[3:])


def sample_mips_trilinear(mips: list[np.ndarray], dirs: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """Lookup along (..., 3) directions at fractional mip level lod (...,): bilinear per level, linear between."""
    d = np.asarray(dirs, np.float64).reshape(-1, 3)
    lv = np.clip(np.asarray(lod, np.float64).reshape(-1), 0.0, len(mips) - 1)
    lo = np.floor(lv).astype(np.int64)
    hi = np.minimum(lo + 1, len(mips) - 1)
    frac = (lv - lo)[:, None]
    out = np.zeros((d.shape[0], mips[0].shape[3]))
    for k in np.unique(np.concatenate([lo, hi])):
        w = np.where(lo == k, 1.0 - frac[:, 0], 0.0) + np.where(hi == k, frac[:, 0], 0.0)
        sel = w > 0
        if np.any(sel):
            out[sel] += w[sel, None] * sample_cube_bilinear(mips[k], d[sel])
    return out.reshape(np.shape(dirs)[:-1] + (mips[0].shape[3],))
