"""Per-splat maths shared by the numpy reference renderer and mirrored line by line in shaders/gs_preprocess.comp.

Each Gaussian is evaluated along each pixel's ray, not through a projected 2D conic: the opacity a ray sees is
``opacity * exp(-m / 2)`` with m the smallest squared Mahalanobis distance of the ray to the splat centre. This is
a property of the ray alone, so a splat reads the same on both cube faces of an edge (no seams), and it is exact
at any field of view where the EWA local-affine approximation of 3DGS is not. It equals 3DGS at the image centre.

3DGS's anti-aliasing dilation (+0.3 px^2 on the 2D covariance) becomes an isotropic 3D variance of the same
screen size at the splat's distance: delta = sqrt(0.3) * pixel_angle * distance, without opacity compensation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import SplatScene, quat_to_matrix
from ..sh import eval_sh_color

DILATION_PX2 = 0.3
ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
DEFAULT_NEAR = 0.01


@dataclass
class PreparedSplats:
    whiten: np.ndarray  # (N, 3, 3): W = diag(1/s') R^T maps world offsets to the splat's unit frame
    origin_local: np.ndarray  # (N, 3): W (origin - mu)
    color: np.ndarray  # (N, 3) SH colour toward the splat from the origin
    opacity: np.ndarray  # (N,)
    cutoff: np.ndarray  # (N,) m beyond which alpha < ALPHA_MIN: 2 ln(255 * opacity)
    distance: np.ndarray  # (N,) from the origin; the sort key
    cov_cut: np.ndarray  # (N, 3, 3): cutoff * Sigma', the ellipsoid whose projection bounds the splat
    alive: np.ndarray  # (N,) bool: in front of the near distance and able to reach ALPHA_MIN


def prepare(scene: SplatScene, origin: np.ndarray, pixel_angle: float, near: float = DEFAULT_NEAR) -> PreparedSplats:
    mu = scene.positions.astype(np.float64) - np.asarray(origin, np.float64)
    dist = np.linalg.norm(mu, axis=1)
    rot = quat_to_matrix(scene.rotations)
    delta2 = DILATION_PX2 * (pixel_angle * dist) ** 2
    s2 = scene.scales.astype(np.float64) ** 2 + delta2[:, None]
    sp = np.sqrt(s2)
    whiten = np.transpose(rot, (0, 2, 1)) / sp[:, :, None]
    origin_local = -np.einsum("nij,nj->ni", whiten, mu)
    dirs = mu / np.maximum(dist, 1e-30)[:, None]
    color = eval_sh_color(scene.sh, dirs)
    op = scene.opacities.astype(np.float64)
    cutoff = 2.0 * np.log(np.maximum(255.0 * op, 1e-30))
    cov = np.einsum("nij,nj,nkj->nik", rot, s2, rot)
    alive = (dist > near) & (cutoff > 0)
    return PreparedSplats(whiten, origin_local, color, op, cutoff, dist, cov * np.maximum(cutoff, 0)[:, None, None],
                          alive)


def ray_mahalanobis(p: PreparedSplats, index: np.ndarray | slice, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For splats ``index`` and rays (P, 3): (m (S, P), in_front (S, P)). m is the squared distance of the ray's
    line to the centre in the whitened frame, |o' x d'|^2 / |d'|^2; the closest point must lie ahead (o'.d' < 0)."""
    dl = np.einsum("sij,pj->spi", p.whiten[index], dirs)
    ol = p.origin_local[index][:, None, :]
    cr = np.cross(ol, dl)
    m = np.sum(cr * cr, -1) / np.sum(dl * dl, -1)
    return m, np.sum(ol * dl, -1) < 0
