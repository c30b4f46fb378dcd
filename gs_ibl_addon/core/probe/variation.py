"""Is one probe enough for a mesh? Probes at the corners of its bounding box against one at its centre.

One probe lights a mesh as if every point of it stood at the probe. The variation of a mesh is the largest
difference, over its 8 bounding-box corners and over normals, between the corner's irradiance and the centre's,
relative to the centre's mean irradiance (luminance, order-2 SH: the light a diffuse surface sees):

    variation = max_corner max_n |E_corner(n) - E_centre(n)| / mean_n E_centre(n)

Above the tolerance a single probe misleads that mesh, and a per-object probe or a grid is needed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..synthetic import fibonacci_sphere
from .grid import eval_irradiance, monomial_coefficients

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec.709, the colour space of scene-linear light
NORMALS = fibonacci_sphere(64)


def box_points(lo, hi) -> np.ndarray:
    """(9, 3): the box's centre, then its 8 corners (x fastest)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = [[(lo, hi)[i & 1][0], (lo, hi)[(i >> 1) & 1][1], (lo, hi)[(i >> 2) & 1][2]] for i in range(8)]
    return np.vstack([(lo + hi) / 2, corners])


@dataclass
class Variation:
    """How much one mesh's light varies across its box."""
    name: str
    variation: float  # the relative difference above (0.23 = 23%)
    corner: tuple[float, float, float]  # the corner that differs most
    centre_irradiance: tuple[float, float, float]  # mean E/pi at the centre, RGB

    def exceeds(self, tolerance: float) -> bool:
        return self.variation > tolerance

    def message(self, tolerance: float) -> str:
        pct = 100 * self.variation
        if not self.exceeds(tolerance):
            return f"{self.name}: light varies {pct:.0f}% across it; one probe is enough"
        return f"{self.name}: light varies {pct:.0f}% across it; use a per-object probe or a grid"


def variation_from_sh(name: str, sh: np.ndarray, points: np.ndarray) -> Variation:
    """``sh`` (9 probes, 9, 3): radiance SH at ``box_points`` (centre first) -> Variation."""
    e = eval_irradiance(monomial_coefficients(sh)[:, None], NORMALS[None]) @ LUMINANCE  # (probes, normals)
    centre = e[0]
    scale = max(float(np.mean(np.maximum(centre, 0.0))), 1e-9)
    diff = np.max(np.abs(e[1:] - centre[None]), axis=1) / scale
    worst = int(np.argmax(diff))
    rgb = eval_irradiance(monomial_coefficients(sh[0]), NORMALS).mean(0)
    return Variation(name, float(diff[worst]), tuple(float(c) for c in points[1 + worst]),
                     tuple(float(c) for c in rgb))


def estimate_variation(renderer, boxes: dict[str, tuple], face_size: int | None = None,
                       progress=None, **settings) -> list[Variation]:
    """Variation of each named box {name: (lo, hi)} (world space) from probes rendered by ``renderer``."""
    from .grid import POINT_FACE_SIZE, bake_sh_points
    names = list(boxes)
    pts = np.concatenate([box_points(*boxes[n]) for n in names]) if names else np.zeros((0, 3))
    sh = bake_sh_points(renderer, pts, face_size or POINT_FACE_SIZE, progress, **settings)
    return [variation_from_sh(n, sh[9 * i:9 * i + 9], pts[9 * i:9 * i + 9]) for i, n in enumerate(names)]
