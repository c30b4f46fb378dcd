"""Cube -> lat-long images in Blender's equirectangular mapping (core.cubemap.latlong_directions).

``cube_to_latlong`` reads each lat-long texel centre's direction from the cube with the seamless bilinear
lookup (sampling.sample_cube_bilinear): no supersampling, so when the lat-long texel is much larger than a
cube texel (near the equator with a small width) it aliases; pick width >= 4 x face size to avoid that.
Near the poles a lat-long texel is much smaller than a cube texel and bilinear interpolation is exact enough.
``sh_irradiance_latlong`` evaluates SH irradiance directly per lat-long texel (smooth, no cube involved).
"""
from __future__ import annotations

import numpy as np

from .. import cubemap
from .sampling import check_cube, sample_cube_bilinear
from .sh_project import sh_irradiance


def _height(width: int, height: int | None) -> int:
    if width < 2:
        raise ValueError(f"lat-long width must be >= 2, got {width}")
    return max(1, width // 2) if height is None else height


def cube_to_latlong(cube: np.ndarray, width: int, height: int | None = None) -> np.ndarray:
    """(6, N, N, C) cube -> (height, width, C) lat-long image (height defaults to width / 2)."""
    a = check_cube(cube)
    return sample_cube_bilinear(a, cubemap.latlong_directions(width, _height(width, height)))


def sh_irradiance_latlong(coeffs: np.ndarray, width: int, height: int | None = None, window: str = "none",
                          window_width: float | None = None) -> np.ndarray:
    """Radiance SH coefficients (K, C) -> (height, width, C) lat-long irradiance E/pi, clamped at 0."""
    dirs = cubemap.latlong_directions(width, _height(width, height))
    return sh_irradiance(coeffs, dirs, window, window_width)
