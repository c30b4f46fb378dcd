"""Cube -> lat-long images in Blender's equirectangular mapping (core.cubemap.latlong_directions).

``cube_to_latlong`` reads each lat-long texel centre's direction from the cube with the seamless bilinear
lookup (sampling.sample_cube_bilinear): no supersampling, so when the lat-long texel is much larger than a
cube texel (near the equator with a small width) it aliases; pick width >= 4 x face size to avoid that.
Near the poles a lat-long texel is much smaller than a cube texel and bilinear interpolation is exact enough.
It goes through a tap table (``latlong_taps``: four flat texel indices and weights per lat-long texel, the few
taps at cube corners split in three), which depends on the sizes only: the lookup's seam rules run once per
table on index arithmetic, and each image is then four gathers. ``cube_to_latlong_reference`` is the plain
lookup, kept as the definition the table is tested against.
``sh_irradiance_latlong`` evaluates SH irradiance directly per lat-long texel (smooth, no cube involved).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import cubemap
from .sampling import _neighbour, check_cube, sample_cube_bilinear
from .sh_project import sh_irradiance


def _height(width: int, height: int | None) -> int:
    if width < 2:
        raise ValueError(f"lat-long width must be >= 2, got {width}")
    return max(1, width // 2) if height is None else height


@dataclass(frozen=True)
class LatlongTaps:
    """Bilinear taps of a (height, width) lat-long image into a cube of face n, as flat texel indices."""
    shape: tuple[int, int]
    index: np.ndarray  # (4, M) flat texel index (face * n + row) * n + column of each tap
    weight: np.ndarray  # (4, M) bilinear weight; a corner tap's weight is on its first texel only
    corner_rows: np.ndarray  # (K,) lat-long texel of each corner tap (flat)
    corner_index: np.ndarray  # (K, 3) the three texels that meet at the corner
    corner_weight: np.ndarray  # (K,) the tap's bilinear weight / 3

    def apply(self, cube: np.ndarray) -> np.ndarray:
        flat = cube.reshape(-1, cube.shape[-1])
        m = self.index.shape[1]
        out = np.empty((m, flat.shape[1]), np.result_type(flat, self.weight))
        for lo in range(0, m, _CHUNK):  # in chunks, as the table was built: 1.5x faster than whole arrays
            hi = min(lo + _CHUNK, m)
            part = flat[self.index[0, lo:hi]] * self.weight[0, lo:hi, None]
            for k in range(1, 4):
                part += flat[self.index[k, lo:hi]] * self.weight[k, lo:hi, None]
            out[lo:hi] = part
        if len(self.corner_rows):  # the two texels a corner adds besides the first (whose weight is w/3 already)
            extra = (flat[self.corner_index[:, 1]] + flat[self.corner_index[:, 2]]) * self.corner_weight[:, None]
            np.add.at(out, self.corner_rows, extra)
        return out.reshape(self.shape + cube.shape[-1:])


# Tables up to this many lat-long texels (64 bytes each: 32 MiB) are kept for the next image of the same sizes
# (Blender re-bakes at the same sizes; the preview and irradiance images are small); larger ones are built per call.
CACHED_TEXELS = 1 << 19
_CHUNK = 1 << 15  # lat-long texels per pass while a table is built


def latlong_taps(n: int, width: int, height: int) -> LatlongTaps:
    """The tap table of a (height, width) lat-long image of a cube of face n (cached when small)."""
    return _cached_taps(n, width, height) if width * height <= CACHED_TEXELS else _build_taps(n, width, height)


@lru_cache(maxsize=4)
def _cached_taps(n: int, width: int, height: int) -> LatlongTaps:
    return _build_taps(n, width, height)


def _build_taps(n: int, width: int, height: int) -> LatlongTaps:
    """The taps sampling.sample_cube_bilinear reads for every lat-long texel centre, by the same seam rules
    (sampling._texel_lookup): a tap off one edge is the neighbouring face's texel along its extrapolated centre
    direction (found by looking up a cube of texel indices), a tap off two edges the mean of the three texels at
    that corner."""
    d = cubemap.latlong_directions(width, height).reshape(-1, 3)
    ids = np.arange(6 * n * n, dtype=np.float64).reshape(6, n, n, 1)  # exact as float64 up to 2^53
    index = np.empty((4, len(d)), np.int64)
    weight = np.empty((4, len(d)))
    rows, corners, corner_w = [], [], []
    for lo in range(0, len(d), _CHUNK):  # chunks keep the temporaries in cache (1.1-2.4x faster measured)
        hi = min(lo + _CHUNK, len(d))
        face, s, t = cubemap.direction_to_face(d[lo:hi])
        x = (s + 1.0) * 0.5 * n - 0.5
        y = (t + 1.0) * 0.5 * n - 0.5
        i0 = np.floor(x).astype(np.int64)
        j0 = np.floor(y).astype(np.int64)
        fx, fy = x - i0, y - j0
        for k, (di, dj, w) in enumerate(((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                                         (0, 1, (1 - fx) * fy), (1, 1, fx * fy))):
            i, j = i0 + di, j0 + dj
            i_in, j_in = (i >= 0) & (i < n), (j >= 0) & (j < n)
            ic, jc = np.clip(i, 0, n - 1), np.clip(j, 0, n - 1)
            idx = (face * n + jc) * n + ic
            edge = i_in ^ j_in
            if np.any(edge):
                idx[edge] = _neighbour(ids, face[edge], i[edge], j[edge])[:, 0].astype(np.int64)
            corner = np.flatnonzero(~(i_in | j_in))
            if len(corner):
                f = face[corner]
                w[corner] /= 3.0
                rows.append(corner + lo)
                corner_w.append(w[corner])
                corners.append(np.stack([idx[corner],
                                         _neighbour(ids, f, i[corner], jc[corner])[:, 0].astype(np.int64),
                                         _neighbour(ids, f, ic[corner], j[corner])[:, 0].astype(np.int64)], 1))
            index[k, lo:hi] = idx
            weight[k, lo:hi] = w
    corner_rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    corner_index = np.concatenate(corners) if corners else np.zeros((0, 3), np.int64)
    corner_weight = np.concatenate(corner_w) if corner_w else np.zeros(0)
    for a in (index, weight, corner_rows, corner_index, corner_weight):
        a.flags.writeable = False  # shared by every caller of the cache
    return LatlongTaps((height, width), index, weight, corner_rows, corner_index, corner_weight)


def cube_to_latlong(cube: np.ndarray, width: int, height: int | None = None) -> np.ndarray:
    """(6, N, N, C) cube -> (height, width, C) lat-long image (height defaults to width / 2)."""
    a = check_cube(cube)
    return latlong_taps(a.shape[1], width, _height(width, height)).apply(a)


def cube_to_latlong_reference(cube: np.ndarray, width: int, height: int | None = None) -> np.ndarray:
    """cube_to_latlong by the plain per-direction lookup (the definition; slower: no table)."""
    a = check_cube(cube)
    return sample_cube_bilinear(a, cubemap.latlong_directions(width, _height(width, height)))


def sh_irradiance_latlong(coeffs: np.ndarray, width: int, height: int | None = None, window: str = "none",
                          window_width: float | None = None) -> np.ndarray:
    """Radiance SH coefficients (K, C) -> (height, width, C) lat-long irradiance E/pi, clamped at 0."""
    dirs = cubemap.latlong_directions(width, _height(width, height))
    return sh_irradiance(coeffs, dirs, window, window_width)
